"""Damper experiments from a `system: damper` config: bench simulation, identification campaigns and single
fits on measured runs, their HDF5 results files, and the summaries the CLI prints.

* Synthetic data (no data file): `identify.runs` fits, run r with its own force-noise realisation and its own
  optimizer stream (`experiment.run_streams(seed, r)`, SeedSequence.spawn), so results do not depend on
  the order or the number of workers. Noise: sigma = noise.level * std(clean force) [N], white, Gaussian.
* Measured data (`data.file` or `--data`): one fit on the training run, J (Fleps-Dezasse Eq. 7) on it and on
  each held-out run of `data.validate`.
* Either way: the real-time check of the identified model (fixed-step RK4 at `identify.realtime_dt`, its
  real-time factor, the largest stable step), and force traces (measured and model) for the figures.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .bench import BenchHistory, read_bench, sawtooth, sine, triangle, with_force
from .config import DamperConfig
from .damper_fit import DamperSpec, RealTime, cost_J, fit, realtime_check
from .data import atomic_path, format_rows
from .errors import InputError
from .experiment import run_streams

RESULT_KIND = "vehid.damper"
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
        fh.write(format_rows(data))  # shortest exact repr of each value


def write_bench_h5(path: str | Path, cfg: DamperConfig, run: SimulatedBench, seed: int) -> None:
    """A bench run in HDF5: /t, /x, /v, /u, /force (noisy), /clean_force, with the resolved config."""
    import h5py

    from .provenance import provenance

    h = run.history
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as h5:
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


def load_measured(cfg: DamperConfig, path: str | Path) -> BenchHistory:
    """A measured bench run with the config's columns, units, window and decimation (SI units)."""
    data = cfg.data
    if data is None:  # no data section: the format `vehid simulate` writes
        columns, units, window, step = dict(BENCH_COLUMNS), {}, None, 1
    else:
        columns = data.columns.model_dump()
        units, window, step = data.units.model_dump(), data.window, data.decimate
    rate = None if data is None else data.sample_rate
    history = read_bench(path, columns, units, sample_rate=rate)
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


# ------------------------------------------------------------------------------------------ identification


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


@dataclass(frozen=True)
class DamperRun:
    """One fit: the estimates of the unknowns, J before and after, J of the truth (the noise floor), effort."""

    index: int
    estimate: NDArray
    J: float
    J_initial: float
    J_truth: float  # NaN when the truth is unknown
    evaluations: int
    penalised: int
    wall_s: float
    history_evals: NDArray = field(repr=False, default_factory=lambda: np.zeros(0, dtype=np.int64))
    history_cost: NDArray = field(repr=False, default_factory=lambda: np.zeros(0))


@dataclass(frozen=True)
class DamperResult:
    """A damper identification: a synthetic campaign (runs >= 1) or a single fit on measured data."""

    config: DamperConfig
    data_file: str | None
    names: tuple[str, ...]
    truth: NDArray | None  # (D,) or None
    start: NDArray  # (D,) configured values of the unknowns
    lower: NDArray
    upper: NDArray
    runs: tuple[DamperRun, ...]
    final_names: tuple[str, ...]  # the whole parameter row of the identified model (run 0)
    final_values: NDArray
    validation: tuple[tuple[str, float], ...]  # (file, J) on held-out runs
    realtime: RealTime
    traces: tuple[Trace, ...]
    wall_s: float

    @property
    def model(self) -> str:
        return self.config.damper.model

    @property
    def estimates(self) -> NDArray:
        return np.array([r.estimate for r in self.runs])

    @property
    def mean(self) -> NDArray:
        return self.estimates.mean(axis=0)

    @property
    def sd(self) -> NDArray:
        return self.estimates.std(axis=0, ddof=1) if len(self.runs) > 1 else np.zeros(len(self.names))

    @property
    def J(self) -> NDArray:
        return np.array([r.J for r in self.runs])

    @property
    def J_truth(self) -> NDArray:
        return np.array([r.J_truth for r in self.runs])

    @property
    def re_percent(self) -> NDArray | None:
        """RE (%) of the mean estimate (SPEC section 4); None without a truth."""
        if self.truth is None:
            return None
        with np.errstate(divide="ignore", invalid="ignore"):
            return 100 * (self.mean - self.truth) / self.truth

    @property
    def nre_percent(self) -> float | None:
        re = self.re_percent
        return None if re is None else float(np.linalg.norm(re))

    @property
    def per_run_nre_percent(self) -> NDArray | None:
        if self.truth is None:
            return None
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.linalg.norm(100 * (self.estimates - self.truth) / self.truth, axis=1)


def _start_point(cfg: DamperConfig, lower: NDArray, upper: NDArray, synthetic: bool, rng) -> NDArray | None:
    """A random start in the box (uniform, from the run's optimizer stream), or None for the configured values."""
    mode = cfg.identify.start
    if mode == "config" or (mode == "auto" and not synthetic):
        return None
    return lower + (upper - lower) * rng.random(lower.size)


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


def _fit_in_stages(cfg, spec, measured, names, box, start, noise_rng, rng) -> _Staged:
    """Fleps-Dezasse section 4.2: each stage fits its unknowns on its own experiment, starting from (and keeping)
    what the stages before it found; synthetic stages draw their noise from the run's noise stream in order."""
    if start is not None:
        spec = spec.with_values(dict(zip(names, start, strict=True)))
    fits, histories = [], []
    for stage in cfg.identify.stages:
        if stage.file is not None:
            history = load_measured(cfg, stage.file)
        elif measured is not None and stage.bench is None:
            history = measured
        else:
            history = simulate_bench(cfg, noise_rng, stage.bench).history
        result = _fit_once(cfg, spec, history, stage.unknowns, {n: box[n] for n in stage.unknowns}, None, rng)
        spec = result.spec
        fits.append(result)
        histories.append(history)
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


def run_identification(
    cfg: DamperConfig,
    data_file: str | Path | None = None,
    on_run: Callable[[int, int], None] | None = None,
) -> DamperResult:
    """Identify the configured damper: a campaign on synthetic data, or one fit on a measured run."""
    started = time.perf_counter()
    data_file = data_file if data_file is not None else (cfg.data.file if cfg.data is not None else None)
    synthetic = data_file is None
    names = tuple(cfg.identify.unknowns)
    box = cfg.search_box()
    lower = np.array([box[n][0] for n in names])
    upper = np.array([box[n][1] for n in names])
    spec = configured_spec(cfg)
    start = np.array([spec.values[n] for n in names])
    truth_known = cfg.identify.truth == "config" or (cfg.identify.truth == "auto" and synthetic)
    truth = start.copy() if truth_known else None
    seed = cfg.identify.seed
    n_runs = cfg.identify.runs if synthetic else 1
    runs, traces, validation, final = [], [], [], None
    measured = None if synthetic else load_measured(cfg, data_file)
    for r in range(n_runs):
        streams = run_streams(seed, r)
        history = simulate_bench(cfg, streams.noise).history if synthetic else measured
        x0 = _start_point(cfg, lower, upper, synthetic, streams.optimizer)
        if cfg.identify.stages:
            result = _fit_in_stages(cfg, spec, measured, names, box, x0, streams.noise, streams.optimizer)
            history = result.histories[-1]
        else:
            result = _fit_once(cfg, spec, history, names, box, x0, streams.optimizer)
        J_truth = float(cost_J(history.force, spec.simulate(history, cfg.bench.substeps))) if truth_known else np.nan
        runs.append(
            DamperRun(
                index=r, estimate=np.array([result.spec.values[n] for n in names]), J=result.J,
                J_initial=result.J_initial, J_truth=J_truth, evaluations=result.evaluations,
                penalised=result.penalised, wall_s=result.wall_s, history_evals=np.asarray(result.history_evals),
                history_cost=np.asarray(result.history_cost),
            )
        )  # fmt: skip
        if r == 0:
            final = result.spec
            if cfg.identify.stages:
                for stage, h in zip(cfg.identify.stages, result.histories, strict=True):
                    traces.append(_trace(f"stage:{stage.name}", h, final, cfg.bench.substeps))
            else:
                label = Path(str(data_file)).stem if data_file else f"bench-{history.source.removeprefix('bench:')}"
                traces.append(_trace(f"train:{label}", history, final, cfg.bench.substeps))
        if on_run is not None:
            on_run(r + 1, n_runs)
    if synthetic:  # the real-time check runs on the bench of run 0
        check_history = simulate_bench(cfg, run_streams(seed, 0).noise).history
    else:
        check_history = measured
        for path in cfg.data.validate_files if cfg.data is not None else ():
            held_out = load_measured(cfg, path)
            trace = _trace(f"validate:{Path(path).stem}", held_out, final, cfg.bench.substeps)
            traces.append(trace)
            validation.append((str(path), trace.J))
    realtime = realtime_check(final, check_history, dt=cfg.identify.realtime_dt)
    return DamperResult(
        config=cfg, data_file=None if synthetic else str(data_file), names=names, truth=truth, start=start,
        lower=lower, upper=upper, runs=tuple(runs), final_names=final.names, final_values=final.row(),
        validation=tuple(validation), realtime=realtime, traces=tuple(traces),
        wall_s=time.perf_counter() - started,
    )  # fmt: skip


# ------------------------------------------------------------------------------------------ results files


def _padded(rows: list[NDArray], fill: float) -> NDArray:
    width = max((r.size for r in rows), default=0)
    out = np.full((len(rows), width), fill, dtype=float)
    for i, r in enumerate(rows):
        out[i, : r.size] = r
    return out


def write_result_h5(path: str | Path, res: DamperResult) -> None:
    """One damper identification in one file, written atomically. Layout (README, "Dampers"):

    attrs: kind = vehid.damper, config_yaml, config_sha256, model, seed, runs, algorithm, noise_level,
    data_file, wall_s, provenance
    /parameters (D,) names; /truth (D,) (NaN when unknown; attr known); /start (D,); /bounds (D, 2)
    /runs/{estimate (N, D), J, J_initial, J_truth, evaluations, penalised, wall_s (N,), history_evals,
    history_cost (N, H)}
    /model/{names, values}: the whole parameter row of the identified model (run 0)
    /validation/{files, J}; /realtime (attrs dt, stable, realtime_factor, largest_stable_dt)
    /traces/<k>/{t, x, v, measured, model} with attrs name, J
    """
    import h5py

    from .provenance import provenance

    cfg, runs = res.config, res.runs
    strings = h5py.string_dtype()
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as h5:
        h5.attrs["kind"] = RESULT_KIND
        h5.attrs["config_yaml"] = cfg.to_yaml()
        h5.attrs["config_sha256"] = cfg.digest()
        h5.attrs["model"] = res.model
        h5.attrs["seed"] = cfg.identify.seed
        h5.attrs["runs"] = len(runs)
        h5.attrs["algorithm"] = cfg.identify.algorithm.name
        h5.attrs["noise_level"] = cfg.noise.level
        h5.attrs["data_file"] = res.data_file or ""
        h5.attrs["wall_s"] = res.wall_s
        for key, value in provenance().items():
            h5.attrs[key] = value
        h5.create_dataset("parameters", data=np.array(res.names, dtype=strings))
        D = len(res.names)
        truth = h5.create_dataset("truth", data=res.truth if res.truth is not None else np.full(D, np.nan))
        truth.attrs["known"] = res.truth is not None
        h5.create_dataset("start", data=res.start)
        h5.create_dataset("bounds", data=np.column_stack([res.lower, res.upper]))
        g = h5.create_group("runs")
        g.create_dataset("estimate", data=np.array([r.estimate for r in runs]))
        for name in ("J", "J_initial", "J_truth", "evaluations", "penalised", "wall_s"):
            g.create_dataset(name, data=np.array([getattr(r, name) for r in runs]))
        g.create_dataset("history_evals", data=_padded([r.history_evals for r in runs], -1).astype(np.int64))
        g.create_dataset("history_cost", data=_padded([r.history_cost for r in runs], np.nan))
        m = h5.create_group("model")
        m.create_dataset("names", data=np.array(res.final_names, dtype=strings))
        m.create_dataset("values", data=res.final_values)
        v = h5.create_group("validation")
        v.create_dataset("files", data=np.array([f for f, _ in res.validation], dtype=strings))
        v.create_dataset("J", data=np.array([j for _, j in res.validation], dtype=float))
        rt = h5.create_group("realtime")
        for name in ("dt", "stable", "realtime_factor", "largest_stable_dt"):
            rt.attrs[name] = getattr(res.realtime, name)
        tg = h5.create_group("traces")
        for k, tr in enumerate(res.traces):
            t = tg.create_group(f"{k:02d}")
            t.attrs["name"], t.attrs["J"] = tr.name, tr.J
            for name in ("t", "x", "v", "measured", "model"):
                t.create_dataset(name, data=getattr(tr, name))


def _text(values) -> tuple[str, ...]:
    return tuple(v.decode() if isinstance(v, bytes) else str(v) for v in values)


def is_result_file(path: str | Path) -> bool:
    """True for a vehid.damper results file."""
    import h5py

    try:
        with h5py.File(path, "r") as h5:
            return h5.attrs.get("kind") == RESULT_KIND
    except OSError:
        return False


def read_result_h5(path: str | Path) -> DamperResult:
    """Read a damper results file back (InputError for a file that is not one)."""
    import yaml

    from .config import config_from_dict
    from .results import open_results

    source = str(path)
    with open_results(path, RESULT_KIND, "damper results file") as h5:
        try:
            cfg = config_from_dict(yaml.safe_load(h5.attrs["config_yaml"]), source=f"{source}:config_yaml")
            g = h5["runs"]
            hev, hco = g["history_evals"][()], g["history_cost"][()]
            runs = tuple(
                DamperRun(
                    index=i, estimate=g["estimate"][i], J=float(g["J"][i]), J_initial=float(g["J_initial"][i]),
                    J_truth=float(g["J_truth"][i]), evaluations=int(g["evaluations"][i]),
                    penalised=int(g["penalised"][i]), wall_s=float(g["wall_s"][i]),
                    history_evals=hev[i][hev[i] >= 0], history_cost=hco[i][~np.isnan(hco[i])],
                )
                for i in range(g["estimate"].shape[0])
            )  # fmt: skip
            rt = h5["realtime"].attrs
            realtime = RealTime(
                cfg.damper.model, float(rt["dt"]), bool(rt["stable"]), float(rt["realtime_factor"]),
                float(rt["largest_stable_dt"]),
            )  # fmt: skip
            traces = tuple(
                Trace(
                    str(t.attrs["name"]), t["t"][()], t["x"][()], t["v"][()], t["measured"][()], t["model"][()],
                    float(t.attrs["J"]),
                )
                for _, t in sorted(h5["traces"].items())
            )  # fmt: skip
            bounds = h5["bounds"][()]
            return DamperResult(
                config=cfg, data_file=str(h5.attrs["data_file"]) or None, names=_text(h5["parameters"][()]),
                truth=h5["truth"][()] if h5["truth"].attrs["known"] else None, start=h5["start"][()],
                lower=bounds[:, 0], upper=bounds[:, 1], runs=runs, final_names=_text(h5["model/names"][()]),
                final_values=h5["model/values"][()],
                validation=tuple(
                    zip(_text(h5["validation/files"][()]), map(float, h5["validation/J"][()]), strict=True)
                ),
                realtime=realtime, traces=traces, wall_s=float(h5.attrs["wall_s"]),
            )  # fmt: skip
        except (KeyError, ValueError, TypeError) as exc:
            raise InputError(f"damper results file is damaged or incomplete ({exc})", source=source) from None


def result_json(res: DamperResult) -> dict:
    """The machine-readable summary (`--json`): SPEC section 5 keys where they apply, plus the damper's own."""

    def obj(values):
        return None if values is None else {n: float(v) for n, v in zip(res.names, values, strict=True)}

    rt = res.realtime
    per_run = res.per_run_nre_percent
    return {
        "kind": RESULT_KIND,
        "model": res.model,
        "data_file": res.data_file,
        "parameters": list(res.names),
        "truth": obj(res.truth),
        "start": obj(res.start),
        "mean": obj(res.mean),
        "re_percent": obj(res.re_percent),
        "nre_percent": res.nre_percent,
        "per_run_nre_percent": None if per_run is None else [float(v) for v in per_run],
        "J": [float(j) for j in res.J],
        "J_truth": None if res.truth is None else [float(j) for j in res.J_truth],
        "J_train": float(np.mean(res.J)),
        "validation_J": {Path(f).name: j for f, j in res.validation},
        "model_row": {n: float(v) for n, v in zip(res.final_names, res.final_values, strict=True)},
        "realtime": {
            "dt": rt.dt,
            "stable": rt.stable,
            "realtime_factor": rt.realtime_factor,
            "largest_stable_dt": rt.largest_stable_dt,
        },  # fmt: skip
        "evaluations_per_run": float(np.mean([r.evaluations for r in res.runs])),
        "runs": len(res.runs),
        "wall_s": res.wall_s,
        "algorithm": res.config.identify.algorithm.name,
        "noise_level": res.config.noise.level,
    }
