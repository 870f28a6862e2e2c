"""Bench runs of a damper config: the configured excitation simulated with force noise, written as a bench file
(CSV or HDF5), and measured runs read through `io.read.read_record` with the config's columns, units, window and
decimation."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ...config import DamperConfig
from ...core.errors import InputError
from ...core.files import atomic_path
from ...core.provenance import provenance
from ...core.store import h5_file
from ...io.measurement import format_rows
from ...io.read import read_record
from ...io.timegrid import NominalRateError
from ...models.bench import BenchHistory, sawtooth, sine, triangle, with_force
from ...models.noise import NoiseModel
from .fit import DamperSpec

BENCH_COLUMNS = {"time": "t", "displacement": "x", "velocity": "v", "control": "u", "force": "force"}


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
    sigma = float(NoiseModel(cfg.noise.level).drawn("force", clean[:, None])[0])  # Eq. 15 on the force
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


MEASURED = NoiseModel(0.0)  # a measured bench run: the force noise estimated from the data (third differences)
MIN_RUN_S = 0.1  # [s] shortest bench run: fit.realtime_check resamples it at steps up to 50 ms
MAX_STEP_S = 0.05  # [s] coarsest sampling step of a bench run: the real-time check's coarsest step
MAX_RUN_S = 300.0  # [s] longest bench run: the real-time check steps it at 10 µs (3e7 steps, about 1.4 GiB)


def _check_time_scale(t: NDArray, columns: Mapping[str, str | None], units: Mapping[str, str], src: str) -> None:
    """A run's sampling step and length within what a damper bench records and the real-time check can step
    (a time column in ms or µs read as seconds lasts 1000 or 10^6 times longer, at a step as much coarser)."""
    dt = float((t[-1] - t[0]) / (t.size - 1))
    span = float(t[-1] - t[0])
    unit = units.get("time", "s")
    if dt > MAX_STEP_S or span > MAX_RUN_S:
        raise InputError(
            f"column '{columns['time']}' read in {unit}: the run lasts {span:.6g} s at a step of {dt:.6g} s; a bench "
            f"run is sampled at least every {MAX_STEP_S:g} s and lasts at most {MAX_RUN_S:g} s (the real-time check "
            f"steps it at 10 µs); is the time column in ms or µs (data.units.time), or cut it with data.window",
            source=src,
            key="data.units.time",
        )


def read_bench(
    path: str | Path,
    columns: Mapping[str, str | None],
    units: Mapping[str, str],
    source_key: str = "data",
    sample_rate: float | None = None,
    variable: str | None = None,
    resample: bool = True,
) -> BenchHistory:
    """A measured bench run, read by `io.read.read_record` (one reader for every format: CSV with numeric or ISO
    8601 time stamps, MDF4, MAT v5/v7.3, HDF5): the columns/channels named by the config (time, displacement,
    force; velocity and control optional) in SI units on one uniform grid starting at t = 0. The velocity, when
    not measured, is the central difference of x; the control, when not measured, is 0.

    `units` gives a quantity's unit (time included); a channel without one has the unit its file declares (MDF4,
    HDF5), else SI. Jittered time stamps are resampled at their median rate (io/timegrid.py). `sample_rate` [Hz]
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
    _check_time_scale(history.t, columns, units, str(path))
    if history.t[-1] - history.t[0] < MIN_RUN_S:
        raise InputError(
            f"the run lasts {history.t[-1] - history.t[0]:.3g} s after window and decimation; a bench run must last at "
            f"least {MIN_RUN_S:g} s (the real-time check of the fitted model steps it at up to 50 ms)",
            source=str(path),
        )
    if np.var(history.force) == 0:
        raise InputError(f"column '{columns['force']}' is constant: J is undefined", source=str(path))
    return history
