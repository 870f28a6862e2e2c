"""The damper on a test bench as a `System` (Fleps-Dezasse section 4): bench runs, the cost J (Eq. 7), fits
(step by step when the config has stages), and what a finished campaign adds: the identified model, J on the
held-out runs, the real-time check and the force traces for the figures.

* Synthetic data (no data file): run r fits the bench run with its own force-noise realisation and its own
  optimizer stream (`experiment.run_streams(seed, r)`). Noise: sigma = noise.level * std(clean force) [N].
* Measured data (`data.file` or `--data`): one fit on the training run; J on each held-out run of
  `data.validate`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import ClassVar

import h5py
import numpy as np
from numpy.typing import NDArray

from ... import __version__
from ...config import DamperConfig
from ...core.errors import InputError
from ...core.h5file import h5_file
from ...core.provenance import provenance
from ...identify.crlb import CramerRao, cramer_rao_outputs
from ...identify.experiment import run_streams
from ...identify.records import RunRecord
from ...io.logger import NominalRateError, read_record
from ...io.measurement import atomic_path, format_rows
from ...models.bench import BenchHistory, sawtooth, sine, triangle, with_force
from ...models.noise import estimate_noise_sigma
from ...optimizers.base import Problem
from ..base import Box, DataFiles, Simulated, System, configured_data_file, data_paths
from .fit import DamperSpec, RealTime, cost_J, fit, j_problem, realtime_check

BENCH_COLUMNS = {"time": "t", "displacement": "x", "velocity": "v", "control": "u", "force": "force"}


# ------------------------------------------------------------------------------------------ bench data


def bench_history(cfg: DamperConfig, bench=None) -> BenchHistory:
    """The configured virtual-bench excitation (motion and control input, no force yet); `bench` replaces
    the config's bench section (a stage's own excitation)."""
    b = bench if bench is not None else cfg.bench
    if b.excitation == "sine":
        return sine(b.amplitude, b.frequency, b.cycles, b.dt, b.control)
    if b.excitation == "sawtooth":
        steps = None if b.steps is None else [tuple(s) for s in b.steps]
        return sawtooth(b.amplitude, b.velocity, b.cycles, b.dt, b.control, steps)
    h = triangle(b.amplitude, b.velocity, 1.0, b.dt, b.control)  # constant_velocity: one slow stroke each way
    return replace(h, source="constant_velocity")


def configured_spec(cfg: DamperConfig) -> DamperSpec:
    """The configured damper: every parameter valued (configured over defaults)."""
    return DamperSpec(cfg.damper.model, cfg.values(), cfg.table_shape, tuple(cfg.damper.effects))


@dataclass(frozen=True)
class SimulatedBench:
    """A simulated bench run: the history with the noisy force, and the clean force [N]."""

    history: BenchHistory
    clean: NDArray
    sigma: float  # force noise standard deviation [N]


def simulate_bench(cfg: DamperConfig, noise_rng: np.random.Generator, bench=None) -> SimulatedBench:
    """Simulate the configured damper on the configured bench (or a stage's `bench`); noise sigma = level *
    std(clean force)."""
    history = bench_history(cfg, bench)
    clean = configured_spec(cfg).simulate(history, cfg.bench.substeps)
    if not np.all(np.isfinite(clean)):
        raise InputError(
            "the configured damper is unstable on this bench (non-finite force); raise bench.substeps or check "
            "the parameters",
            source=cfg.source,
            key="damper.parameters",
        )
    sigma = float(cfg.noise.level * np.std(clean))
    noisy = clean + sigma * noise_rng.standard_normal(clean.size)
    return SimulatedBench(with_force(history, noisy, source=f"bench:{history.source}"), clean, sigma)


def write_bench_csv(path: str | Path, history: BenchHistory, comments: list[str]) -> None:
    """A bench file: columns t [s], x [m], v [m/s], u [-], force [N]; `#` comment lines first; atomic."""
    data = np.column_stack([history.t, history.x, history.v, history.u, history.force])
    header = "\n".join(f"# {c}" for c in comments)
    with atomic_path(path) as tmp, open(tmp, "w") as fh:
        fh.write(header + "\n" if header else "")
        fh.write("t,x,v,u,force\n")
        fh.write(format_rows(data))


def write_bench_h5(path: str | Path, cfg: DamperConfig, run: SimulatedBench, seed: int) -> None:
    """A bench run in HDF5: /t, /x, /v, /u, /force (noisy), /clean_force, with the resolved config."""

    h = run.history
    with h5_file(path) as h5:
        h5.attrs["kind"] = "vehid.bench"
        h5.attrs["config_yaml"] = cfg.to_yaml()
        h5.attrs["config_sha256"] = cfg.digest()
        h5.attrs["noise_level"] = cfg.noise.level
        h5.attrs["noise_sigma_N"] = run.sigma
        h5.attrs["seed"] = seed
        for key, value in provenance().items():
            h5.attrs[key] = value
        for name, values, unit in (("t", h.t, "s"), ("x", h.x, "m"), ("v", h.v, "m/s"), ("u", h.u, "1"),
                                   ("force", h.force, "N"), ("clean_force", run.clean, "N")):  # fmt: skip
            h5.create_dataset(name, data=values).attrs["unit"] = unit


MIN_RUN_S = 0.1  # [s] shortest bench run: damper_fit.realtime_check resamples it at steps up to 50 ms


def read_bench(
    path: str | Path,
    columns: Mapping[str, str | None],
    units: Mapping[str, str],
    source_key: str = "data",
    sample_rate: float | None = None,
    variable: str | None = None,
    resample: bool = True,
) -> BenchHistory:
    """A measured bench run, read by `logger.read_record` (one reader for every format: CSV with numeric or ISO
    8601 time stamps, MDF4, MAT v5/v7.3, HDF5): the columns/channels named by the config (time, displacement,
    force; velocity and control optional) in SI units on one uniform grid starting at t = 0. The velocity, when
    not measured, is the central difference of x; the control, when not measured, is 0.

    `units` gives a quantity's unit (time included); a channel without one has the unit its file declares (MDF4,
    HDF5), else SI. Jittered time stamps are resampled at their median rate (logger.py). `sample_rate` [Hz]
    declares the rate of a file whose time column was printed with too few digits to be uniform: the column must
    then increase with steps within 5 % of 1 / rate, and the grid is rebuilt from it (the samples kept as they
    are). `variable` names the MAT struct / HDF5 group holding the channels. `resample=False` refuses channels
    at different rates, jittered stamps and samples off the grid (`read_record`)."""
    for role in ("time", "displacement", "force"):
        if not columns.get(role):
            raise InputError(f"no column given for the {role}", key=f"{source_key}.columns.{role}")
    channels = {role: str(name) for role, name in columns.items() if name and role != "time"}
    given = {role: unit for role, unit in units.items() if role in channels}
    try:
        record = read_record(
            path, channels, given, time=str(columns["time"]), time_unit=units.get("time", "s"),
            nominal_rate=sample_rate, variable=variable, resample=resample,
        )  # fmt: skip
    except NominalRateError as exc:
        raise InputError(exc.detail, source=exc.source, key=f"{source_key}.sample_rate") from None
    t = record.t
    x = record.channels["displacement"]
    v = record.channels.get("velocity")
    if v is None:
        v = np.gradient(x, t)
    u = record.channels.get("control", np.zeros(t.size))
    return BenchHistory(t, x, v, u, record.channels["force"], source=record.source)


def load_measured(cfg: DamperConfig, path: str | Path) -> BenchHistory:
    """A measured bench run with the config's columns, units, window and decimation (SI units)."""
    data = cfg.data
    if data is None:  # no data section: the format `vehid simulate` writes
        columns, units, window, step = dict(BENCH_COLUMNS), {}, None, 1
    else:
        columns = data.columns.model_dump()
        # only the units the config sets: a channel without one has its file's declared unit (MDF4), else SI
        units = data.units.model_dump(include=data.units.model_fields_set)
        window, step = data.window, data.decimate
    rate = None if data is None else data.sample_rate
    variable = None if data is None else data.variable
    resample = True if data is None else data.resample
    history = read_bench(path, columns, units, sample_rate=rate, variable=variable, resample=resample)
    if window is not None:
        history = history.window(history.t[0] + window[0], history.t[0] + window[1])
    if step > 1:
        f = history.force
        history = replace(
            history, t=history.t[::step], x=history.x[::step], v=history.v[::step], u=history.u[::step],
            force=None if f is None else f[::step],
        )  # fmt: skip
    if history.t.size < 3:
        raise InputError(f"only {history.t.size} samples left after window and decimation", source=str(path))
    if history.t[-1] - history.t[0] < MIN_RUN_S:
        raise InputError(
            f"the run lasts {history.t[-1] - history.t[0]:.3g} s after window and decimation; a bench run must last at "
            f"least {MIN_RUN_S:g} s (the real-time check of the fitted model steps it at up to 50 ms)",
            source=str(path),
        )
    if np.var(history.force) == 0:
        raise InputError(f"column '{columns['force']}' is constant: J is undefined", source=str(path))
    return history


# ------------------------------------------------------------------------------------------ fits


@dataclass(frozen=True)
class Trace:
    """Measured and model force on one bench run (for the figures), with J on it."""

    name: str
    t: NDArray
    x: NDArray
    v: NDArray
    measured: NDArray
    model: NDArray
    J: float


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


def _stage_histories(cfg: DamperConfig, measured: BenchHistory | None, noise_rng) -> list[BenchHistory]:
    """Each stage's bench run: its own file, the measured run, or its (or the config's) excitation simulated with
    noise drawn from the run's noise stream in stage order."""
    histories = []
    for stage in cfg.identify.stages:
        if stage.file is not None:
            histories.append(load_measured(cfg, stage.file))
        elif measured is not None and stage.bench is None:
            histories.append(measured)
        else:
            histories.append(simulate_bench(cfg, noise_rng, stage.bench).history)
    return histories


def _fit_in_stages(cfg, spec, measured, names, box, start, noise_rng, rng) -> _Staged:
    """Fleps-Dezasse section 4.2: each stage fits its unknowns on its own experiment, starting from (and keeping)
    what the stages before it found."""
    if start is not None:
        spec = spec.with_values(dict(zip(names, start, strict=True)))
    fits = []
    histories = _stage_histories(cfg, measured, noise_rng)
    for stage, history in zip(cfg.identify.stages, histories, strict=True):
        result = _fit_once(cfg, spec, history, stage.unknowns, {n: box[n] for n in stage.unknowns}, None, rng)
        spec = result.spec
        fits.append(result)
    evals = np.concatenate([f.history_evals + sum(g.evaluations for g in fits[:k]) for k, f in enumerate(fits)])
    return _Staged(
        spec=spec, J=fits[-1].J, J_initial=fits[0].J_initial, evaluations=sum(f.evaluations for f in fits),
        penalised=sum(f.penalised for f in fits), wall_s=sum(f.wall_s for f in fits), history_evals=evals,
        history_cost=np.concatenate([f.history_cost for f in fits]), stage_J=tuple(f.J for f in fits),
        histories=tuple(histories),
    )  # fmt: skip


def _trace(name: str, history: BenchHistory, spec: DamperSpec, substeps: int) -> Trace:
    model = spec.simulate(history, substeps)
    return Trace(name, history.t, history.x, history.v, history.force, model, float(cost_J(history.force, model)))


@dataclass(frozen=True)
class Findings:
    """What a damper campaign adds after its runs: the identified model (run 0's, every parameter), J on the
    held-out runs, the real-time check, and measured/model force traces (training and held out)."""

    model: str
    names: tuple[str, ...]  # the whole parameter row of the identified model
    values: NDArray
    validation: tuple[tuple[str, float], ...]  # (file, J) on held-out runs
    realtime: RealTime
    traces: tuple[Trace, ...]

    def write_h5(self, group) -> None:
        """Into the results file's /damper group (results.py)."""
        strings = h5py.string_dtype()
        group.attrs["model"] = self.model
        group.create_dataset("model_names", data=np.array(self.names, dtype=strings))
        group.create_dataset("model_values", data=self.values)
        v = group.create_group("validation")
        v.create_dataset("files", data=np.array([f for f, _ in self.validation], dtype=strings))
        v.create_dataset("J", data=np.array([j for _, j in self.validation], dtype=float))
        rt = group.create_group("realtime")
        for name in ("dt", "stable", "realtime_factor", "largest_stable_dt"):
            rt.attrs[name] = getattr(self.realtime, name)
        tg = group.create_group("traces")
        for k, tr in enumerate(self.traces):
            t = tg.create_group(f"{k:02d}")
            t.attrs["name"], t.attrs["J"] = tr.name, tr.J
            for name in ("t", "x", "v", "measured", "model"):
                t.create_dataset(name, data=getattr(tr, name))

    def to_json(self, campaign) -> dict:
        """The damper's keys of the JSON summary: J per run and of the truth, held-out J, the model, real time."""
        rt, recs = self.realtime, campaign.records
        return {
            "model": self.model,
            "J": [float(r.cost) for r in recs],
            "J_truth": None if campaign.truth is None else [float(r.truth_cost) for r in recs],
            "J_train": float(np.mean([r.cost for r in recs])),
            "validation_J": {Path(f).name: j for f, j in self.validation},
            "model_row": {n: float(v) for n, v in zip(self.names, self.values, strict=True)},
            "realtime": {
                "dt": rt.dt,
                "stable": rt.stable,
                "realtime_factor": rt.realtime_factor,
                "largest_stable_dt": rt.largest_stable_dt,
            },  # fmt: skip
        }

    @classmethod
    def read_h5(cls, group) -> Findings:
        """From a results file's /damper group (KeyError for a damaged one)."""
        model = str(group.attrs["model"])
        rt = group["realtime"].attrs
        realtime = RealTime(
            model, float(rt["dt"]), bool(rt["stable"]), float(rt["realtime_factor"]), float(rt["largest_stable_dt"])
        )
        traces = tuple(
            Trace(
                str(t.attrs["name"]),
                t["t"][()],
                t["x"][()],
                t["v"][()],
                t["measured"][()],
                t["model"][()],
                float(t.attrs["J"]),
            )  # fmt: skip
            for _, t in sorted(group["traces"].items())
        )
        files = _text(group["validation/files"][()])
        return cls(
            model=model, names=_text(group["model_names"][()]), values=group["model_values"][()],
            validation=tuple(zip(files, map(float, group["validation/J"][()]), strict=True)), realtime=realtime,
            traces=traces,
        )  # fmt: skip


def _text(values) -> tuple[str, ...]:
    return tuple(v.decode() if isinstance(v, bytes) else str(v) for v in values)


class DamperSystem(System):
    """A damper on a test bench: the configured model fitted by J (Eq. 7) to bench runs."""

    name: ClassVar[str] = "damper"
    objective: ClassVar[str] = "J"
    findings_type: ClassVar[type] = Findings

    def __init__(self, config: DamperConfig, data_file: DataFiles = None):
        cfg = config
        files = data_paths(configured_data_file(cfg, data_file))
        if len(files) > 1:
            raise InputError(
                f"a damper is fitted to one bench run at a time, got {len(files)} files ({', '.join(files)}); "
                "give --data once (held-out runs go to data.validate)",
                source=cfg.source,
            )
        self.config = cfg
        self.data_file = files[0] if files else None
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
            sigma = float(estimate_noise_sigma(self.measured.force[:, None])[0])
            self.sigma_source = "estimated from the data (third differences)"
        self.sigma = {"force": np.array([sigma])}

    @property
    def residual_samples(self) -> int:
        return int(self.first.t.size)

    @property
    def _bounds(self) -> dict[str, tuple[float, float]]:
        """The search box by name."""
        return {n: (lo, hi) for n, lo, hi in zip(self.names, self.box.lower, self.box.upper, strict=True)}

    def data_files(self) -> tuple[str, ...]:
        stages = tuple(str(s.file) for s in self.config.identify.stages if s.file is not None)
        return super().data_files() + self.held_out + stages

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

    def _chi2(self, J: float, history: BenchHistory) -> float:
        """Residual power over the noise power: J var(F) / sigma² (NaN without noise)."""
        sigma = float(self.sigma["force"][0])
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
        spec, substeps = self.spec, self.config.bench.substeps
        J_truth = (
            float(cost_J(history.force, spec.simulate(history, substeps))) if self.box.truth is not None else np.nan
        )
        return RunRecord(
            index=index, estimate=np.array([result.spec.values[n] for n in self.names]), cost=result.J,
            evaluations=result.evaluations, penalised=result.penalised, wall_s=result.wall_s,
            history_evals=np.asarray(result.history_evals), history_cost=np.asarray(result.history_cost),
            truth_cost=J_truth, chi2=self._chi2(result.J, history), initial_cost=result.J_initial,
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
            for stage, h in zip(cfg.identify.stages, histories, strict=True):
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
