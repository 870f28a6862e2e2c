"""Statistical campaigns: N identification runs of one task, in parallel, resumable, bit-reproducible.

Run i identifies from its own noise realisation with its own optimizer stream (`experiment.run_streams`),
so its result depends only on the config, the seed and i: never on `--jobs` or on which runs were done
before an interruption. Each finished run is saved (atomically) to a checkpoint directory beside the
output before the campaign goes on, and a restarted campaign picks those runs up.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .config import Config, config_from_dict
from .crlb import CramerRao
from .data import atomic_path
from .errors import InputError
from .experiment import run_streams
from .identification import Task, build_task
from .optimizers import get_optimizer


@dataclass(frozen=True)
class RunRecord:
    """The outcome of one identification run."""

    index: int
    estimate: NDArray  # (D,)
    cost: float
    evaluations: int
    penalised: int
    wall_s: float
    history_evals: NDArray  # cumulative evaluations at each record of the best cost
    history_cost: NDArray  # best cost so far
    truth_cost: float = float("nan")  # cost of the true parameters on this run's data (NaN: truth unknown)
    chi2: float = float("nan")  # noise-weighted residual power per sample at the estimate (~1 for an adequate model)

    @property
    def converged(self) -> bool | None:
        """Found the global minimum's basin: a cost no higher than the truth's on the same data (None: unknown)."""
        if not np.isfinite(self.truth_cost):
            return None
        return bool(self.cost <= self.truth_cost * (1 + 1e-9))

    def save(self, path: Path) -> None:
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            np.savez(fh, **{k: np.asarray(v) for k, v in self.__dict__.items()})

    @classmethod
    def load(cls, path: Path) -> RunRecord:
        with np.load(path) as z:
            return cls(
                index=int(z["index"]),
                estimate=z["estimate"],
                cost=float(z["cost"]),
                evaluations=int(z["evaluations"]),
                penalised=int(z["penalised"]),
                wall_s=float(z["wall_s"]),
                history_evals=z["history_evals"],
                history_cost=z["history_cost"],
                truth_cost=float(z["truth_cost"]),
                chi2=float(z["chi2"]),
            )


@dataclass(frozen=True)
class Summary:
    """Figures of merit of a campaign (SPEC section 4), computed once."""

    names: tuple[str, ...]
    truth: NDArray | None
    mean: NDArray  # mean estimate over runs (D,)
    sd: NDArray  # standard deviation of the estimates over runs (D,)
    re_percent: NDArray | None  # RE of the mean (D,)
    nre_percent: float | None  # NRE of the mean (the paper's figure)
    per_run_re_percent: NDArray | None  # (N, D)
    per_run_nre_percent: NDArray | None  # (N,)
    crlb_re_sd_percent: NDArray  # (D,)
    crlb_nre_rms_percent: float
    evaluations: NDArray  # (N,)
    penalised: int
    wall_s: float
    converged: int | None = None  # runs whose cost is no higher than the truth's (None: truth unknown)
    chi2_median: float = float("nan")  # median over runs of the residual power over the noise power
    residual_samples: int = 0  # R, the number of weighted residuals behind chi2

    @property
    def chi2_limit(self) -> float:
        """Largest chi² per sample an adequate model gives: 1 + 5 sd of a chi² mean over R samples."""
        return 1.0 + 5.0 * np.sqrt(2.0 / max(self.residual_samples, 1))

    @property
    def model_inadequate(self) -> bool:
        """The residual is far above the noise the data implies: the model lacks something (or the noise level
        set by noise.level is too small)."""
        return bool(np.isfinite(self.chi2_median) and self.chi2_median > self.chi2_limit)

    @property
    def per_run_nre_median(self) -> float | None:
        return None if self.per_run_nre_percent is None else float(np.median(self.per_run_nre_percent))

    @property
    def per_run_nre_rms(self) -> float | None:
        return None if self.per_run_nre_percent is None else float(np.sqrt(np.mean(self.per_run_nre_percent**2)))

    @property
    def nre_over_crlb(self) -> float | None:
        """Per-run NRE RMS over the bound's NRE RMS: 1.0 is the physical limit."""
        rms = self.per_run_nre_rms
        if rms is None or not np.isfinite(self.crlb_nre_rms_percent) or self.crlb_nre_rms_percent <= 0:
            return None
        return rms / self.crlb_nre_rms_percent

    @property
    def re_sd_percent(self) -> NDArray:
        """Spread of the estimates over runs, relative to the truth (or to the mean when unknown) [%]."""
        ref = self.truth if self.truth is not None else self.mean
        return 100.0 * self.sd / np.abs(ref)


def summarise(
    names, truth, records: list[RunRecord], bound: CramerRao, wall_s: float, residual_samples: int = 0
) -> Summary:
    """Statistics of a list of runs against the truth (when known) and the Cramér–Rao bound."""
    est = np.array([r.estimate for r in records])
    mean, sd = est.mean(axis=0), est.std(axis=0, ddof=1) if len(records) > 1 else np.zeros(est.shape[1])
    re = nre = per_re = per_nre = None
    if truth is not None:
        re = 100.0 * (mean - truth) / truth
        nre = float(np.linalg.norm(re))
        per_re = 100.0 * (est - truth) / truth
        per_nre = np.linalg.norm(per_re, axis=1)
    return Summary(
        names=tuple(names),
        truth=truth,
        mean=mean,
        sd=sd,
        re_percent=re,
        nre_percent=nre,
        per_run_re_percent=per_re,
        per_run_nre_percent=per_nre,
        crlb_re_sd_percent=bound.re_sd_percent,
        crlb_nre_rms_percent=bound.nre_rms_percent,
        evaluations=np.array([r.evaluations for r in records]),
        penalised=int(sum(r.penalised for r in records)),
        wall_s=wall_s,
        converged=None if truth is None else int(sum(bool(r.converged) for r in records)),
        chi2_median=float(np.median([r.chi2 for r in records])),
        residual_samples=residual_samples,
    )


@dataclass(frozen=True)
class Campaign:
    """A finished campaign: the task's description, every run, the bound and the summary."""

    config: Config
    data_file: str | None
    names: tuple[str, ...]
    truth: NDArray | None
    nominal: NDArray
    lower: NDArray
    upper: NDArray
    sigma: dict[str, NDArray]
    sigma_source: str
    records: tuple[RunRecord, ...]
    bound: CramerRao
    summary: Summary


# ------------------------------------------------------------------------------------------ running


def identify_run(task: Task, index: int) -> RunRecord:
    """Run `index` of the campaign: its own data (noise) and its own optimizer stream."""
    ident = task.config.identify
    problem = task.problem(task.reference(index))
    # Diagnostic, not charged to the budget: the truth's cost on this run's data tells a converged run.
    truth_cost = float(problem.cost(task.truth[None, :])[0]) if task.truth is not None else float("nan")
    algorithm = ident.algorithm
    optimizer = get_optimizer(algorithm.name, algorithm.population, algorithm.iterations)
    x0 = task.nominal if ident.start == "nominal" else None
    result = optimizer.minimize(problem, run_streams(ident.seed, index).optimizer, budget=ident.budget, x0=x0)
    # Diagnostic, not charged: residual power over noise power at the estimate tells whether the model fits.
    _, residuals = problem.residuals(result.x[None, :])
    chi2 = float(np.mean(residuals**2))
    return RunRecord(
        index=index,
        estimate=result.x,
        cost=result.cost,
        evaluations=result.evaluations,
        penalised=result.penalised,
        wall_s=result.wall_s,
        history_evals=result.history_evals,
        history_cost=result.history_cost,
        truth_cost=truth_cost,
        chi2=chi2,
    )


_WORKER_TASK: Task | None = None


def _init_worker(raw_config: dict, source: str, data_file: str | None) -> None:
    global _WORKER_TASK
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)  # one BLAS thread per worker process: see vehid_cli/__init__.py
    _WORKER_TASK = build_task(config_from_dict(raw_config, source), data_file)


def _worker_run(index: int) -> RunRecord:
    assert _WORKER_TASK is not None
    return identify_run(_WORKER_TASK, index)


def campaign_key(config: Config, data_file: str | None) -> str:
    """Identity of a campaign's results: the resolved config, the data file's bytes and the code version
    (runs of different code are never mixed in one campaign)."""
    from . import __version__
    from .provenance import git_commit

    h = hashlib.sha256(f"{config.digest()} {__version__} {git_commit()}".encode())
    if data_file is not None:
        h.update(Path(data_file).read_bytes())
    return h.hexdigest()


class Checkpoint:
    """Per-run records of an unfinished campaign, in a directory beside its output file."""

    def __init__(self, directory: Path, key: str):
        self.directory = directory
        self.key = key

    def open(self) -> dict[int, RunRecord]:
        """Read back the runs the directory holds (refusing another campaign's runs). A checkpoint without
        runs (a campaign that failed before finishing one) holds nothing to protect and is started afresh."""
        stamp = self.directory / "campaign.json"
        if self.directory.exists() and not any(self.directory.glob("run-*.npz")):
            self.remove()
        if self.directory.exists():
            try:
                meta = json.loads(stamp.read_text())
            except (OSError, ValueError):
                raise InputError(
                    "checkpoint directory has no readable campaign.json; remove it to start afresh",
                    source=str(self.directory),
                ) from None
            if meta.get("key") != self.key:
                raise InputError(
                    "checkpoint belongs to a different config or data file; remove it or choose another -o",
                    source=str(self.directory),
                )
        done = {}
        for path in sorted(self.directory.glob("run-*.npz")):
            try:
                record = RunRecord.load(path)
            except Exception:  # noqa: BLE001 - a damaged record is redone, never trusted
                path.unlink()
                continue
            done[record.index] = record
        return done

    def save(self, record: RunRecord) -> None:
        """Persist one finished run (creating the checkpoint, stamped with the campaign key, on the first)."""
        if not self.directory.exists():
            self.directory.mkdir(parents=True)
            with atomic_path(self.directory / "campaign.json") as tmp:
                tmp.write_text(json.dumps({"key": self.key}))
        record.save(self.directory / f"run-{record.index:05d}.npz")

    def remove(self) -> None:
        if self.directory.is_dir():
            for path in self.directory.iterdir():
                path.unlink()
            self.directory.rmdir()


def run_campaign(
    config: Config,
    data_file: str | Path | None = None,
    *,
    jobs: int | None = None,
    checkpoint_dir: Path | None = None,
    on_run: Callable[[int, int], None] | None = None,
) -> Campaign:
    """Run every run of the configured campaign (resuming from `checkpoint_dir` if it holds some)."""
    data_file = None if data_file is None else str(data_file)
    task = build_task(config, data_file)
    n_runs = config.identify.runs
    start = time.perf_counter()
    bound = task.bound()
    checkpoint = Checkpoint(checkpoint_dir, campaign_key(config, data_file)) if checkpoint_dir else None
    done = checkpoint.open() if checkpoint else {}
    done = {i: r for i, r in done.items() if i < n_runs}
    todo = [i for i in range(n_runs) if i not in done]
    if on_run:
        on_run(len(done), n_runs)

    def finished(record: RunRecord) -> None:
        done[record.index] = record
        if checkpoint:
            checkpoint.save(record)
        if on_run:
            on_run(len(done), n_runs)

    jobs = max(1, min(jobs or os.cpu_count() or 1, len(todo) or 1))
    if jobs == 1:
        from threadpoolctl import threadpool_limits

        with threadpool_limits(1):  # the same BLAS threading as the workers of a parallel campaign
            for index in todo:
                finished(identify_run(task, index))
    else:
        raw = config.model_dump(mode="json", exclude_none=True)
        with ProcessPoolExecutor(jobs, initializer=_init_worker, initargs=(raw, config.source, data_file)) as pool:
            pending = {pool.submit(_worker_run, i) for i in todo}
            try:
                while pending:
                    complete, pending = wait(pending, return_when=FIRST_COMPLETED)
                    for future in complete:
                        finished(future.result())
            except BaseException:
                for future in pending:
                    future.cancel()
                raise
    records = tuple(done[i] for i in range(n_runs))
    summary = summarise(
        task.names, task.truth, list(records), bound, time.perf_counter() - start, task.residual_samples
    )
    return Campaign(
        config=config,
        data_file=data_file,
        names=task.names,
        truth=task.truth,
        nominal=task.nominal,
        lower=task.lower,
        upper=task.upper,
        sigma=task.sigma,
        sigma_source=task.sigma_source,
        records=records,
        bound=bound,
        summary=summary,
    )


def checkpoint_dir_for(output: Path) -> Path:
    """Where the finished runs of the campaign bound for `output` wait: `<output>.partial/`."""
    return output.with_name(output.name + ".partial")


def run_campaign_to_file(
    config: Config,
    output: Path,
    data_file: str | Path | None = None,
    *,
    jobs: int | None = None,
    on_run: Callable[[int, int], None] | None = None,
) -> Campaign:
    """Run (or resume) a campaign, write its HDF5 file atomically, then drop its checkpoint."""
    from .results import write_campaign_h5

    partial = checkpoint_dir_for(Path(output))
    campaign = run_campaign(config, data_file, jobs=jobs, checkpoint_dir=partial, on_run=on_run)
    write_campaign_h5(output, campaign)
    Checkpoint(partial, "").remove()
    return campaign
