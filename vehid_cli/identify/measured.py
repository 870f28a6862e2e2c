"""A measured vehicle run as the identification needs it: the layout's channels and the road on one time grid.

Two kinds of file are read:

* the SPEC's measurement CSV (t, road1..road4, acc1..acc4, disp1..disp4 in SI units), for the paper's corner
  layout when the config maps no channels: `data.read_measurement`, as `vehid simulate` writes it;
* anything a data logger or a test engineer writes (MDF4, MAT v5/v7.3, HDF5, CSV with ISO stamps), through
  `io.read.read_record`: the config's `data.channels` say which channel of the file is which sensor (a name left
  out is looked up as itself), `data.units` its unit, and channels at different rates meet on one grid.

A channel slower than the grid is compared only at its own samples (`observed`): up-sampled values between them
carry no new information, and counting them would overstate what the run knows. Sensor offsets are removed
(each channel's mean over the first second, the car at rest) or left to the fit (`data.offsets: identify`).
The road is the rig's actuator displacements (road1..road4), one measured profile per side (track1, track2: the
rear wheels meet it wheelbase/speed later), or the configured road on the run's time grid.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..config import Config
from ..core.errors import InputError
from ..core.streams import experiment_rng
from ..core.units import SI_FACTORS
from ..io.measurement import read_measurement
from ..io.read import read_record
from ..io.record import Record, remove_offset
from ..models.road import road_function
from ..models.sensors import FAMILY
from .experiment import Experiment, check_time_step

ROAD = ("road1", "road2", "road3", "road4")
TRACKS = ("track1", "track2")
MIN_OWN_SAMPLES = 8  # samples of its own a measured channel needs in a run (third differences, shapes)


@dataclass(frozen=True)
class MeasuredRun:
    """One measured run on a uniform grid: the road under each tyre and the channels of the families used."""

    t: NDArray  # (n,) [s], uniform, from 0 or the file's first stamp
    road: NDArray  # (n, 4) [m]
    outputs: dict[str, NDArray]  # family -> (n, k) [m/s² or m], the layout's channels of that family
    observed: dict[str, NDArray] | None  # family -> (n, k) bool: the channel's own samples (None: every sample)
    source: str
    raw: dict[str, NDArray] | None = None  # family -> (n, k) the channels as read [SI], before offsets are removed
    # (the outputs' own arrays when none are)
    units: dict[str, tuple[str, str]] | None = None  # channel -> (the unit it was read in, where that came from)

    @property
    def dt(self) -> float:
        return float((self.t[-1] - self.t[0]) / (self.t.size - 1))


def _legacy(config: Config) -> bool:
    """The SPEC's measurement CSV: the paper's layout, no channel mapping, the road from road1..road4."""
    data = config.data
    plain = not (data.channels or data.units or data.window or data.rate or data.time or data.variable)
    return config.layout is None and plain and config.road.input == "actuators" and data.offsets == "none"


def read_run(config: Config, path: str | Path, families: tuple[str, ...]) -> MeasuredRun:
    """Read run `path` for the config's layout: the channels of `families` and the road (config.road.input)."""
    source = str(path)
    if Path(path).suffix.lower() in (".csv", ".txt") and _legacy(config):
        m = read_measurement(path, need_responses=bool(families))
        outputs = {}
        for family in families:
            values = getattr(m, family)
            if values is None:
                raise InputError(
                    f"objective '{config.identify.objective}' with sensors '{config.sensors}' needs columns "
                    f"{family}1..{family}4, which this file lacks",
                    source=source,
                )
            outputs[family] = values
        return MeasuredRun(t=m.t, road=m.road, outputs=outputs, observed=None, source=source)

    layout, data = config.sensor_layout(), config.data
    sensors = [name for family in families for name in layout.names(family)]
    road_names = {"actuators": ROAD, "tracks": TRACKS, "config": ()}[config.road.input]
    ours = sensors + list(road_names)
    channels = {name: data.channels.get(name, name) for name in ours}
    units = configured_units(config, ours)
    record = read_record(
        path, channels, units, time=data.time, window=data.window, rate=data.rate, variable=data.variable,
        time_unit=data.time_unit, resample=data.resample,
    )  # fmt: skip
    check_units(config, record, units, path)
    record = rewired(record, data.invert, data.swap)
    as_read = record
    if data.offsets == "remove":
        record = remove_offset(record, sensors, "first_second")
    outputs, observed = {}, {}
    for family in families:
        names = layout.names(family)
        outputs[family] = np.column_stack([record.channel(n) for n in names])
        observed[family] = np.column_stack([_observed(record, n) for n in names])
        _enough(record, names, observed[family])
    # the channels as read: the same arrays as the outputs unless offsets were removed (a long record's channels
    # are tens of MB per copy)
    raw = dict(outputs) if record is as_read else {f: np.column_stack([as_read.channel(n) for n in layout.names(f)])
                                             for f in families}  # fmt: skip
    every = all(mask.all() for mask in observed.values())
    road = _road(config, record, road_names)
    origin = {n: (units[n], "data.units" if n in data.units else "data.units (its family)") for n in units}
    origin |= {n: (record.declared[n], "the file") for n in sensors if n not in units and record.declared.get(n)}
    origin |= {n: ("SI", "default: no unit in data.units, its family or the file") for n in sensors if n not in origin}
    return MeasuredRun(
        t=record.t,
        road=road,
        outputs=outputs,
        observed=None if every else observed,
        source=source,
        raw=raw,
        units=origin,
    )


def configured_units(config: Config, names) -> dict[str, str]:
    """Each channel's unit as the config gives it: its own entry in data.units, else its family's (data.units.acc,
    data.units.disp; road inputs are displacements); a channel without either takes the unit its file declares."""
    layout, units = config.sensor_layout(), config.data.units
    family = {s.name: FAMILY[s.kind] for s in layout.sensors} | dict.fromkeys(ROAD + TRACKS, "disp")
    out = {}
    for name in names:
        unit = units.get(name) or units.get(family.get(name, ""))
        if unit:
            out[name] = unit
    return out


def check_units(config: Config, record: Record, units: dict[str, str], path) -> None:
    """A unit the config gives that the file contradicts (it declares another for the channel) is an InputError
    naming the config's key: the two cannot both be right."""
    for name, unit in units.items():
        theirs = record.declared.get(name, "")
        if theirs and theirs in SI_FACTORS and SI_FACTORS.get(unit) != SI_FACTORS[theirs]:
            key = f"data.units.{name}" if name in config.data.units else "data.units (its family)"
            raise InputError(
                f"the config reads '{name}' in {unit} ({key}) but {path} declares {theirs} for it; remove the "
                "config's unit to take the file's, or correct the one that is wrong",
                source=config.source,
                key=key,
            )


def rewired(record: Record, invert, swap) -> Record:
    """The record with the chain's declared mistakes undone: data.invert's channels negated, data.swap's pairs
    exchanged (their samples and sample times)."""
    if not invert and not swap:
        return record
    channels, stamps, rates = dict(record.channels), dict(record.stamps), dict(record.rates)
    for name in invert:
        channels[name] = -channels[name]
    for a, b in swap:
        for table in (channels, stamps, rates):
            table[a], table[b] = table[b], table[a]
    return replace(record, channels=channels, stamps=stamps, rates=rates)


def _enough(record: Record, names, observed: NDArray) -> None:
    """Each channel with at least MIN_OWN_SAMPLES samples of its own in the record: its noise is estimated from
    third differences, and its checks compare shapes."""
    for name, count in zip(names, observed.sum(axis=0), strict=True):
        if count < MIN_OWN_SAMPLES:
            raise InputError(
                f"channel '{name}' has {int(count)} samples of its own in the record ({record.t.size} grid samples "
                f"over {record.t[-1] - record.t[0]:.6g} s, where all channels overlap): at least {MIN_OWN_SAMPLES} "
                "are needed to estimate its noise and check it",
                source=record.source,
            )


def _observed(record: Record, name: str) -> NDArray:
    """(n,) bool: the grid samples where channel `name` was sampled itself."""
    mask = np.zeros(record.t.size, dtype=bool)
    mask[record.native_samples(name)] = True
    return mask


def _road(config: Config, record: Record, names: tuple[str, ...]) -> NDArray:
    """The road (n, 4) [m] under corners 1..4 on the record's grid."""
    t = record.t
    if config.road.input == "config":
        return road_function(config.road, config.vehicle.L, experiment_rng(config.identify.seed))(t - t[0])
    if config.road.input == "actuators":
        return np.column_stack([record.channel(n) for n in names])
    # tracks: side 1 under corners 1 (front) and 4 (rear), side 2 under 2 and 3; the rear meets it L / V later
    delay = config.vehicle.L / config.road.V
    side1, side2 = record.channel("track1"), record.channel("track2")

    def later(y: NDArray) -> NDArray:
        return np.interp(t - delay, t, y, left=y[0])

    return np.column_stack([side1, side2, later(side2), later(side1)])


def experiment_of(config: Config, run: MeasuredRun) -> Experiment:
    """The configured car on a measured run's road and time grid (the uniform grid its stamps approximate)."""
    t = run.t[0] + np.arange(run.t.size) * run.dt
    check_time_step(config, run.dt, f"{run.source}: the time step")
    return Experiment(config=config, t=t, road=run.road, road_source=run.source)
