"""The damper on a test bench as a `System` (Fleps-Dezasse section 4): bench runs, the cost J (Eq. 7), fits
(step by step when the config has stages), and what a finished campaign adds: the identified model, J on the
held-out runs, the real-time check and the force traces for the figures.

* Synthetic data (no data file): run r fits the bench run with its own force-noise realisation and its own
  optimizer stream (`experiment.run_streams(seed, r)`). Noise: sigma = noise.level * std(clean force) [N].
* Measured data (`data.file` or `--data`): one fit on the training run; J on each held-out run of
  `data.validate`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

import numpy as np
from numpy.typing import NDArray

from ... import __version__
from ...config import DamperConfig
from ...core.errors import InputError
from ...core.progress import ProgressHook
from ...core.streams import run_streams
from ...identify.crlb import CramerRao, cramer_rao_outputs
from ...identify.records import Campaign, RunRecord
from ...identify.source import DataFiles, DataSource
from ...models.bench import BenchHistory
from ...optimizers.base import Problem
from ..base import Box, Log, Simulated, System
from .bench import (
    MEASURED,
    bench_history,
    configured_spec,
    load_measured,
    simulate_bench,
    write_bench_csv,
    write_bench_h5,
)
from .findings import Findings, Trace
from .fit import DamperSpec, cost_J, fit, j_problem, realtime_check

# ------------------------------------------------------------------------------------------ bench data


# ------------------------------------------------------------------------------------------ fits


def _fit_once(cfg, spec, history, names, box, start, rng) -> tuple:
    ident = cfg.identify
    budget = ident.budget or ident.algorithm.population * ident.algorithm.iterations
    if start is not None:
        spec = spec.with_values(dict(zip(names, start, strict=True)))
    return fit(
        spec, history, names, box, algorithm=ident.algorithm.name, budget=budget,
        population=ident.algorithm.population, rng=rng, substeps=cfg.bench.substeps,
    )  # fmt: skip


@dataclass(frozen=True)
class _Staged:
    """The outcome of a step-by-step identification, shaped like one fit (the last stage's J)."""

    spec: DamperSpec
    J: float
    J_initial: float
    evaluations: int
    penalised: int
    wall_s: float
    history_evals: NDArray
    history_cost: NDArray
    stage_J: tuple[float, ...]
    histories: tuple[BenchHistory, ...]
    sigma: float  # the last stage's force noise [N]: drawn for a simulated stage, else estimated from its data


def _stage_histories(cfg: DamperConfig, measured: BenchHistory | None, noise_rng) -> list[tuple[BenchHistory, float]]:
    """Each stage's bench run and its force noise [N]: its own file or the measured run (noise estimated from its
    force), or its (or the config's) excitation simulated with noise drawn from the run's noise stream in stage
    order (the noise it was drawn with)."""
    out = []
    for stage in cfg.identify.stages:
        if stage.file is not None or (measured is not None and stage.bench is None):
            history = load_measured(cfg, stage.file) if stage.file is not None else measured
            out.append((history, float(MEASURED.estimated("force", history.force[:, None])[0])))
        else:
            run = simulate_bench(cfg, noise_rng, stage.bench)
            out.append((run.history, run.sigma))
    return out


def _last_stage_samples(cfg: DamperConfig, measured: BenchHistory | None) -> int:
    """How many force samples the last stage's J (and so a staged run's chi2) is over."""
    stage = cfg.identify.stages[-1]
    if stage.file is not None:
        return int(load_measured(cfg, stage.file).t.size)
    if measured is not None and stage.bench is None:
        return int(measured.t.size)
    return int(bench_history(cfg, stage.bench).t.size)


def _fit_in_stages(cfg, spec, measured, names, box, start, noise_rng, rng) -> _Staged:
    """Fleps-Dezasse section 4.2: each stage fits its unknowns on its own experiment, starting from (and keeping)
    what the stages before it found."""
    if start is not None:
        spec = spec.with_values(dict(zip(names, start, strict=True)))
    fits = []
    staged = _stage_histories(cfg, measured, noise_rng)
    histories = [h for h, _ in staged]
    for stage, history in zip(cfg.identify.stages, histories, strict=True):
        result = _fit_once(cfg, spec, history, stage.unknowns, {n: box[n] for n in stage.unknowns}, None, rng)
        spec = result.spec
        fits.append(result)
    evals = np.concatenate([f.history_evals + sum(g.evaluations for g in fits[:k]) for k, f in enumerate(fits)])
    return _Staged(
        spec=spec, J=fits[-1].J, J_initial=fits[0].J_initial, evaluations=sum(f.evaluations for f in fits),
        penalised=sum(f.penalised for f in fits), wall_s=sum(f.wall_s for f in fits), history_evals=evals,
        history_cost=np.concatenate([f.history_cost for f in fits]), stage_J=tuple(f.J for f in fits),
        histories=tuple(histories), sigma=staged[-1][1],
    )  # fmt: skip


def _trace(name: str, history: BenchHistory, spec: DamperSpec, substeps: int) -> Trace:
    model = spec.simulate(history, substeps)
    return Trace(name, history.t, history.x, history.v, history.force, model, float(cost_J(history.force, model)))


if TYPE_CHECKING:  # the loop is imported by `diagnose` alone: a campaign does not load it
    from ...diagnose.result import Diagnosis


class DamperSystem(System):
    """A damper on a test bench: the configured model fitted by J (Eq. 7) to bench runs."""

    name: ClassVar[str] = "damper"
    objective: ClassVar[str] = "J"
    findings_type: ClassVar[type] = Findings
    # a bench test is the same experiment for every model fitted to it: the model, its configured values and what is
    # identified are the method (`damper.*`, `identify.*`); the bench, the data and the noise are not
    method_keys: ClassVar[tuple[str, ...]] = (*System.method_keys, "damper", "identify")

    def __init__(self, config: DamperConfig, source: DataSource | DataFiles = None):
        cfg = config
        source = DataSource.resolve(config, source)
        files = source.runs
        if len(files) > 1:
            raise InputError(
                f"a damper is fitted to one bench run at a time, got {len(files)} files ({', '.join(files)}); "
                "give --data once (held-out runs go to data.validate)",
                source=cfg.source,
            )
        self.config = cfg
        self.source = source
        self.spec = configured_spec(cfg)
        names = tuple(cfg.identify.unknowns)
        box = cfg.search_box()
        nominal = np.array([self.spec.values[n] for n in names])
        synthetic = self.data_file is None
        truth_known = cfg.identify.truth == "config" or (cfg.identify.truth == "auto" and synthetic)
        self.box = Box(
            names, np.array([box[n][0] for n in names]), np.array([box[n][1] for n in names]), nominal,
            nominal.copy() if truth_known else None,
        )  # fmt: skip
        self.measured = None if synthetic else load_measured(cfg, self.data_file)
        self.held_out = () if synthetic or cfg.data is None else tuple(str(p) for p in cfg.data.validate_files)
        if synthetic:  # run 0's bench run, kept: its bound, traces and real-time check all use it
            run0 = simulate_bench(cfg, run_streams(cfg.identify.seed, 0).noise)
            self.first, sigma = run0.history, run0.sigma
            self.sigma_source = f"force noise {cfg.noise.level:g} x std of the clean force"
        else:
            self.first = self.measured
            sigma = float(MEASURED.estimated("force", self.measured.force[:, None])[0])
            self.sigma_source = "estimated from the data (third differences)"
        self.sigma = {"force": np.array([sigma])}

    @property
    def residual_samples(self) -> int:
        if self.config.identify.stages:  # a staged run's J and chi2 are the last stage's
            return _last_stage_samples(self.config, self.measured)
        return int(self.first.t.size)

    @property
    def _bounds(self) -> dict[str, tuple[float, float]]:
        """The search box by name."""
        return {n: (lo, hi) for n, lo, hi in zip(self.names, self.box.lower, self.box.upper, strict=True)}

    @property
    def channel_names(self) -> tuple[str, ...]:
        return ("force",)

    @classmethod
    def results_attributes(cls, config: DamperConfig) -> dict[str, str]:
        return {"model": config.damper.model}

    @classmethod
    def diagnose(
        cls, config: DamperConfig, data: tuple[str, ...], validate: tuple[str, ...], log: Log | None,
        progress: ProgressHook | None = None,
    ) -> Diagnosis:  # fmt: skip
        """The bench's loop (`diagnosis.diagnose_damper`) on one run (else data.file), judged on `validate` (else
        data.validate)."""
        if len(data) > 1:
            raise InputError("a damper is diagnosed on one --data run (its validation runs: --validate)",
                             source=config.source)  # fmt: skip
        from .diagnosis import diagnose_damper  # the loop's machinery only for `vehid diagnose`

        return diagnose_damper(config, data[0] if data else None, validate or None, log=log, progress=progress)

    @classmethod
    def tables(cls, campaigns: Sequence[Campaign], files: Sequence[str]) -> list:
        from .report import parameter_table

        return [parameter_table(c, f) for c, f in zip(campaigns, files, strict=True)]

    @classmethod
    def render(cls, campaigns: Sequence[Campaign], files: Sequence[str], fmt: str, published: dict | None) -> str:
        from .report import csv_text, latex, markdown

        return {"md": markdown, "latex": latex}.get(fmt, csv_text)(list(campaigns), list(files))

    @classmethod
    def figures(cls, campaigns: Sequence[Campaign], files: Sequence[str], out_dir: Path) -> list[Path]:
        from .plots import write_damper_plots, write_fitted_force_plots

        stems = [Path(f).stem for f in files]
        return write_damper_plots([c.findings for c in campaigns], stems, out_dir) + write_fitted_force_plots(
            campaigns, stems, out_dir
        )

    @classmethod
    def plot_simulation(cls, simulated: Simulated, path: Path) -> None:
        from .plots import plot_bench

        plot_bench(simulated.run.history, simulated.run.clean, path, simulated.title)

    @classmethod
    def write_simulation(
        cls, config: DamperConfig, target: Path, seed: int, road: Path | None = None, origin: str = ""
    ) -> Simulated:
        """The configured bench run, force noise from run 0's noise stream: a bench file (t, x, v, u, force)."""
        if road is not None:
            raise InputError("--road is for vehicle configs; a damper config takes its motion from 'bench'")
        cfg = config
        run = simulate_bench(cfg, run_streams(seed, 0).noise)
        h = run.history
        if target.suffix.lower() == ".csv":
            comments = [
                f"vehid {__version__} {origin}".rstrip(),
                f"config sha256 {cfg.digest()}",
                f"damper {cfg.damper.model} on a {cfg.bench.excitation} bench; force noise "
                f"{100 * cfg.noise.level:g} % of std (sigma {run.sigma:.6g} N), seed {seed}",
                "units: t [s], x [m], v [m/s], u [-], force [N]",
            ]
            write_bench_csv(target, h, comments)
        else:
            write_bench_h5(target, cfg, run, seed)
        summary = f"{h.t.size} samples at dt = {h.dt * 1e3:g} ms, force noise {100 * cfg.noise.level:g} %"
        return Simulated(run, summary, f"{cfg.damper.model} on a {cfg.bench.excitation} bench")

    def reference(self, run: int) -> BenchHistory:
        if self.measured is not None or run == 0:
            return self.first
        return simulate_bench(self.config, run_streams(self.config.identify.seed, run).noise).history

    def problem(self, reference: BenchHistory) -> Problem:
        return j_problem(self.spec, reference, self.names, self._bounds, self.config.bench.substeps)[0]

    def bound(self, at: NDArray | None = None) -> CramerRao:
        """The Cramér–Rao bound of the bench run (run 0's motion) for white force noise of the campaign's sigma, at
        `at` (default: the truth, or the configured values); NaN when the noise is zero or unknown."""
        sigma = float(self.sigma["force"][0])
        if not sigma > 0 or self.config.identify.stages:  # stages fit on several runs: no single-run bound
            return super().bound(at)
        if at is None:
            at = self.box.truth if self.box.truth is not None else self.box.nominal
        history, substeps = self.reference(0), self.config.bench.substeps
        with np.errstate(all="ignore"):
            return cramer_rao_outputs(
                self.names, at, lambda X: self.spec.simulate_batch(self.names, X, history, substeps).force, sigma
            )

    def start(self, rng: np.random.Generator) -> NDArray | None:
        """A random start in the box (uniform, from the run's optimizer stream), or None for the configured values."""
        mode = self.config.identify.start
        if mode == "config" or (mode == "auto" and self.data_file is not None):
            return None
        lower, upper = self.box.lower, self.box.upper
        return lower + (upper - lower) * rng.random(lower.size)

    def _chi2(self, J: float, history: BenchHistory, sigma: float | None = None) -> float:
        """Residual power over the noise power: J var(F) / sigma² (NaN without noise); `sigma` the noise of
        `history` when it is not the campaign's run (a stage's bench run has its own)."""
        sigma = float(self.sigma["force"][0]) if sigma is None else sigma
        return float(J * np.var(history.force) / sigma**2) if sigma > 0 else float("nan")

    def _fit(self, index: int) -> tuple[_Staged, BenchHistory]:
        cfg = self.config
        streams = run_streams(cfg.identify.seed, index)
        synthetic = self.data_file is None
        history = simulate_bench(cfg, streams.noise).history if synthetic else self.measured
        x0 = self.start(streams.optimizer)
        box = self._bounds
        if cfg.identify.stages:
            result = _fit_in_stages(
                cfg, self.spec, self.measured, self.names, box, x0, streams.noise, streams.optimizer
            )
            return result, result.histories[-1]
        return _fit_once(cfg, self.spec, history, self.names, box, x0, streams.optimizer), history

    def identify_run(self, index: int) -> RunRecord:
        result, history = self._fit(index)
        sigma = result.sigma if isinstance(result, _Staged) else None  # a staged run's chi2: the last stage's noise
        spec, substeps = self.spec, self.config.bench.substeps
        J_truth = (
            float(cost_J(history.force, spec.simulate(history, substeps))) if self.box.truth is not None else np.nan
        )
        return RunRecord(
            index=index, estimate=np.array([result.spec.values[n] for n in self.names]), cost=result.J,
            evaluations=result.evaluations, penalised=result.penalised, wall_s=result.wall_s,
            history_evals=np.asarray(result.history_evals), history_cost=np.asarray(result.history_cost),
            truth_cost=J_truth, chi2=self._chi2(result.J, history, sigma), initial_cost=result.J_initial,
        )  # fmt: skip

    def conclude(self, records: tuple[RunRecord, ...]) -> Findings:
        """Run 0's model: its row, its traces on the training runs and held-out runs, the real-time check."""
        cfg, substeps = self.config, self.config.bench.substeps
        final = self.spec.with_values(dict(zip(self.names, records[0].estimate, strict=True)))
        traces, validation = [], []
        if cfg.identify.stages:
            noise = run_streams(cfg.identify.seed, 0).noise
            if self.measured is None:  # run 0 drew the config's bench run first (see _fit)
                simulate_bench(cfg, noise)
            histories = _stage_histories(cfg, self.measured, noise)
            for stage, (h, _) in zip(cfg.identify.stages, histories, strict=True):
                traces.append(_trace(f"stage:{stage.name}", h, final, substeps))
        else:
            history = self.first
            label = Path(self.data_file).stem if self.data_file else f"bench-{history.source.removeprefix('bench:')}"
            traces.append(_trace(f"train:{label}", history, final, substeps))
        for path in self.held_out:
            trace = _trace(f"validate:{Path(path).stem}", load_measured(cfg, path), final, substeps)
            traces.append(trace)
            validation.append((path, trace.J))
        realtime = realtime_check(final, self.first, dt=cfg.identify.realtime_dt)
        return Findings(cfg.damper.model, final.names, final.row(), tuple(validation), realtime, tuple(traces))
