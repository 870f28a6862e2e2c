"""Statistical campaigns: N identification runs of one task, in parallel, resumable, bit-reproducible.

Run i identifies from its own noise realisation with its own optimizer stream (`experiment.run_streams`),
so its result depends only on the config, the seed and i: never on `--jobs`, on the executor (a local
process pool or a Dask cluster, `executor.py`) or on which runs were done before an interruption. Each
finished run is saved (atomically, fsynced) to a checkpoint directory beside the output before the campaign
goes on, and a restarted campaign picks those runs up; a damaged record is discarded (with a warning) and its
run redone, never trusted. The campaign file is written atomically, under a lock (`locking.py`) that keeps
two processes from running the same campaign into the same file.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .config import Config
from .crlb import CramerRao
from .data import atomic_path, remove_stale_temporaries
from .errors import InputError
from .executor import Executor, LocalExecutor
from .experiment import run_streams
from .identification import Task, build_task
from .optimizers import get_optimizer
from .optimizers.base import Problem

Log = Callable[[str], None]
PENALTY = Problem.__dataclass_fields__["penalty"].default  # the cost of a NaN/Inf evaluation (optimizers/base.py)


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
    def at_penalty(self) -> bool:
        """The run found no parameter set the model simulates usefully: its best cost is the penalty (or worse),
        so its estimate is meaningless."""
        return bool(self.cost >= PENALTY)

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
    at_penalty: int = 0  # runs that found no usable parameter set (best cost = the penalty): meaningless estimates
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
        at_penalty=int(sum(r.at_penalty for r in records)),
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
    data_sha256: str | None = None  # SHA-256 of the data file's bytes (None: simulated data)


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
    # Parameter sets that make the model blow up overflow on their way to a NaN/Inf cost: the optimizer gives
    # them the finite penalty and counts them (`penalised`), so NumPy's floating-point warnings are noise here.
    with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
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


def data_digest(data_file: str | Path | None) -> str | None:
    """SHA-256 of a data file's bytes (None without one)."""
    return None if data_file is None else hashlib.sha256(Path(data_file).read_bytes()).hexdigest()


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

    def __init__(self, directory: Path, key: str, log: Log | None = None):
        self.directory = directory
        self.key = key
        self.log = log

    def _warn(self, message: str) -> None:
        if self.log is not None:
            self.log(f"warning: {message}")

    def open(self) -> dict[int, RunRecord]:
        """Read back the runs the directory holds (refusing another campaign's runs). A checkpoint without
        runs (a campaign that failed before finishing one) holds nothing to protect and is started afresh.
        Unfinished writes (temporary files a kill left) are removed; a record that does not read back whole
        (truncated, CRC error, wrong run) is discarded with a warning and its run is redone."""
        stamp = self.directory / "campaign.json"
        if self.directory.is_dir():
            for tmp in self.directory.glob(".*.tmp"):
                tmp.unlink()
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
            if not isinstance(meta, dict) or meta.get("key") != self.key:
                raise InputError(
                    "checkpoint belongs to a different config or data file; remove it or choose another -o",
                    source=str(self.directory),
                )
        done = {}
        for path in sorted(self.directory.glob("run-*.npz")):
            try:
                record = RunRecord.load(path)
                if path.name != f"run-{record.index:05d}.npz":
                    raise ValueError(f"it holds run {record.index}")
            except Exception as exc:  # noqa: BLE001 - a damaged record is redone, never trusted
                self._warn(f"{path}: damaged checkpoint record ({exc.__class__.__name__}: {exc}); discarded, "
                           "the run is redone")  # fmt: skip
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
        """Delete the checkpoint: its runs first, campaign.json last, so that a kill midway leaves one that still
        opens (stamped, with fewer runs or none), never runs without their stamp."""
        if self.directory.is_dir():
            stamp = self.directory / "campaign.json"
            for path in self.directory.iterdir():
                if path != stamp:
                    path.unlink()
            with contextlib.suppress(FileNotFoundError):
                stamp.unlink()
            self.directory.rmdir()


def run_campaign(
    config: Config,
    data_file: str | Path | None = None,
    *,
    jobs: int | None = None,
    executor: Executor | None = None,
    checkpoint_dir: Path | None = None,
    on_run: Callable[[int, int], None] | None = None,
    log: Log | None = None,
) -> Campaign:
    """Run every run of the configured campaign (resuming from `checkpoint_dir` if it holds some).

    The runs execute on `executor` (default: a `LocalExecutor(jobs)` for this campaign alone); each finished
    run is checkpointed before the next result is taken. `on_run(done, total)` reports progress; `log` receives
    warnings (damaged checkpoint records)."""
    data_file = None if data_file is None else str(data_file)
    task = build_task(config, data_file)
    n_runs = config.identify.runs
    start = time.perf_counter()
    bound = task.bound()
    checkpoint = Checkpoint(checkpoint_dir, campaign_key(config, data_file), log) if checkpoint_dir else None
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

    with contextlib.ExitStack() as stack:
        if executor is None:
            executor = stack.enter_context(LocalExecutor(jobs))
        results = executor.map_unordered(identify_run, task, todo)
        stack.callback(results.close)
        for record in results:
            finished(record)
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
        data_sha256=data_digest(data_file),
    )


def checkpoint_dir_for(output: Path) -> Path:
    """Where the finished runs of the campaign bound for `output` wait: `<output>.partial/`."""
    return output.with_name(output.name + ".partial")


def finished_campaign(output: Path, config: Config, data_file: str | Path | None = None) -> Campaign | None:
    """The campaign `output` holds if it is whole (checksum verified) and of this campaign's key: the config (by
    `campaign_file_digest`, the test a sweep skips by), the data file's bytes and the code version; else None."""
    from . import __version__
    from .provenance import git_commit
    from .results import CAMPAIGN_KIND, campaign_file_digest, check_integrity, open_results, read_campaign_h5

    try:
        if check_integrity(output) is None or campaign_file_digest(output) != config.digest():
            return None
        with open_results(output, CAMPAIGN_KIND, "campaign file") as h5:
            made = tuple(str(h5.attrs.get(k, "")) for k in ("vehid_version", "git_commit", "data_sha256"))
        if made != (__version__, git_commit(), data_digest(data_file) or ""):
            return None
        return read_campaign_h5(output)
    except (InputError, OSError):  # missing, damaged or foreign: not finished
        return None


def run_campaign_to_file(
    config: Config,
    output: Path,
    data_file: str | Path | None = None,
    *,
    jobs: int | None = None,
    executor: Executor | None = None,
    on_run: Callable[[int, int], None] | None = None,
    log: Log | None = None,
    attrs: Mapping[str, str] | None = None,
    lock: bool = True,
) -> Campaign:
    """Run (or resume) a campaign, write its HDF5 file atomically, then drop its checkpoint (kept if the write
    fails: the rerun finishes from it). A checkpoint beside a finished file of this campaign is stale: removed,
    and that file's campaign returned.

    With `lock` (the default) the output's lock is held throughout: `locking.Busy` (an InputError) if another
    process holds it. Pass `lock=False` only when the caller holds it. `attrs` are extra root attributes of the
    file (a sweep records its varied keys)."""
    from .locking import exclusive
    from .results import write_campaign_h5

    output = Path(output)
    with exclusive(output) if lock else contextlib.nullcontext():
        remove_stale_temporaries(output)
        partial = checkpoint_dir_for(output)
        if partial.exists():  # a kill during the clean-up after the file was written leaves a stale checkpoint
            finished = finished_campaign(output, config, data_file)
            if finished is not None:
                Checkpoint(partial, "").remove()
                if log is not None:
                    log(f"note: {output} is complete for this config; removed the stale checkpoint {partial}")
                return finished
        campaign = run_campaign(
            config, data_file, jobs=jobs, executor=executor, checkpoint_dir=partial, on_run=on_run, log=log
        )
        write_campaign_h5(output, campaign, attrs=attrs)
        Checkpoint(partial, "").remove()
    return campaign
