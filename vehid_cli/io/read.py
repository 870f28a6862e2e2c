"""Logger files (issue 13): a recorded run as named channels on one uniform time grid, in SI units.

Vehicle data loggers write ASAM MDF4 (`.mf4`/`.mdf`), test engineers pass on MATLAB files (`.mat`, v5 or the
HDF5-based v7.3), HDF5 (`.h5`/`.hdf5`) and CSV exports (`.csv`/`.txt`, numeric or ISO 8601 time stamps): one
module each in `io.formats`, found by the file's suffix. `read_record` reads the channels a caller names (our
name -> the name in the file), converts them to SI (`core.units.UNITS`: one unit table for the whole package,
`core.units`) and puts them on one uniform grid (`io.timegrid`: anti-alias low-pass before down-sampling, cubic
spline otherwise, jitter resampled, gaps refused; `resample=False` refuses any resampling). The Record
(`io.record`) keeps each channel's own rate and sample times.

Every problem a user can fix is an `InputError` naming the file and the channel (exit status 2).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..core.errors import InputError, clip
from ..core.hints import did_you_mean
from ..core.units import UNITS, unit_factor
from .formats import FORMATS, SUFFIXES, LoggerFormat, Raw
from .record import Record
from .timegrid import (
    NATIVE_MATCH,
    check_channel,
    common_grid,
    on_nominal_rate,
    onto,
    rate_of,
    refuse_off_grid,
    refuse_resampling,
)

UNIT_LENGTH = 64  # characters: a longer unit string is no unit (and is not quoted whole)


def read_record(
    path: str | Path,
    channels: Mapping[str, str],
    units: Mapping[str, str] | None = None,
    *,
    time: str | None = None,
    window: tuple[float, float] | None = None,
    rate: float | None = None,
    variable: str | None = None,
    time_unit: str = "s",
    nominal_rate: float | None = None,
    resample: bool = True,
) -> Record:
    """Read the `channels` (our name -> the name in the file) of a logger file as one Record in SI units.

    The format is the suffix's (`io.formats`). `units` gives a channel's unit (our name -> unit, e.g. 'g',
    'mm'); without it, the unit the file declares (MDF4 channel unit, HDF5 `unit` attribute), else SI.
    `time` names the time column/vector (CSV, MAT, HDF5; default `t` or `time`; MDF4 channels carry their own);
    CSV time stamps may be ISO 8601 date-times, read as seconds after the first. Without a time vector, `rate`
    [Hz] gives the sampling rate; with one, `rate` is the rate of the grid (default: the highest channel rate;
    below a channel's rate, the channel is low-passed before it is down-sampled). `window` (start, stop) [s]
    keeps start <= t - t0 < stop, t0 the start of the record; times are kept, t0 is 0. `variable` names the MAT
    struct (or HDF5 group) that holds the channels when there is more than one. `time_unit` (core.units.UNITS['time'])
    is the unit of a numeric time column/vector (CSV, MAT, HDF5; MDF4 stamps are seconds). `nominal_rate` [Hz]
    declares stamps printed with too few digits to be uniform: each step must be within 5 % of 1 / rate, and the
    stamps are rebuilt as t0 + k / rate with the samples kept as they are (NominalRateError otherwise).
    `resample=False` reads samples as they are, never resampled: channels at different rates (beyond 1 %), a grid
    `rate` other than theirs, jittered stamps or samples between the grid points are an InputError naming the
    channels and rates. The Record keeps each channel's own rate and sample times (`Record.native_samples`)."""
    path = Path(path)
    src = str(path)
    units = dict(units or {})
    fmt = _format_of(path, channels, units, rate, nominal_rate, time_unit, window)
    raw = fmt.read(path, channels, time=time, rate=rate, variable=variable)
    declared = {ours: r.unit.strip() for ours, r in raw.items()}
    steps = _in_si(raw, channels, units, time_unit, nominal_rate, src)
    rates = {ours: rate_of(r, steps[ours]) for ours, r in raw.items()}
    if not resample:
        refuse_resampling(raw, channels, steps, rates, rate, src)
    grid, grid_rate, start = common_grid(raw, channels, rates, rate, src)
    if not resample:
        for ours, r in raw.items():
            refuse_off_grid(ours, channels[ours], r, steps[ours], grid, src)
    values = {
        ours: onto(r, steps[ours], grid, grid_rate, f"'{ours}' ('{channels[ours]}')", src) for ours, r in raw.items()
    }
    t, values = _windowed(np.arange(grid.size) / grid_rate, values, window, src)
    near = NATIVE_MATCH / grid_rate
    stamps = {ours: r.t - start for ours, r in raw.items()}
    stamps = {ours: s[(s >= t[0] - near) & (s <= t[-1] + near)] for ours, s in stamps.items()}
    return Record(t=t, channels=values, source=src, rates=rates, stamps=stamps, declared=declared)


@contextmanager
def read_ahead(paths: Iterable[str | Path]) -> Iterator[None]:
    """The logger files `paths` read now, and `read_record`'s first read of each within the block served from memory
    (`LoggerFormat.read_ahead`: every channel of an MDF4 file; the formats read in this process keep nothing).

    Why: a command reads its files before it imports the compiled kernels. MDF4 is read in a child interpreter
    (asammdf and pandas: 110-120 MiB while it reads a 60 s record), and numba maps its LLVM library at import
    (70-100 MiB resident, with the page cache's history): one after the other, their memory does not add up
    (issue 26's 300 MiB). A file that cannot be read ahead is read, and reported, where it is used."""
    formats = set()
    try:
        for path in paths:
            fmt = FORMATS.get(Path(path).suffix.lower())
            if fmt is not None:
                formats.add(fmt)
                fmt.read_ahead(Path(path))
        yield
    finally:  # an interrupted read-ahead too: nothing kept past the block
        for fmt in formats:
            fmt.forget()


def _format_of(
    path: Path,
    channels: Mapping[str, str],
    units: Mapping[str, str],
    rate: float | None,
    nominal_rate: float | None,
    time_unit: str,
    window: tuple[float, float] | None,
) -> LoggerFormat:
    """The format of the file's suffix, once the arguments are checked (and the file is there)."""
    src = str(path)
    fmt = FORMATS.get(path.suffix.lower())
    if fmt is None:
        raise InputError(f"unknown logger file type '{path.suffix}'; expected one of {', '.join(SUFFIXES)}", source=src)
    if not channels:
        raise InputError("no channels named to read", source=src)
    for ours in units:
        if ours not in channels:
            raise InputError(
                f"a unit is given for '{ours}', which is not a channel read ({', '.join(channels)})", source=src
            )
    if rate is not None and not (math.isfinite(rate) and rate > 0):
        raise InputError(f"rate must be a positive number of Hz, got {rate}", source=src)
    if nominal_rate is not None and not (math.isfinite(nominal_rate) and nominal_rate > 0):
        raise InputError(f"nominal rate must be a positive number of Hz, got {nominal_rate}", source=src)
    if time_unit not in UNITS["time"]:
        raise InputError(
            f"unknown time unit '{time_unit}'{did_you_mean(time_unit, UNITS['time'])}; known: "
            f"{', '.join(UNITS['time'])}",
            source=src,
        )
    if window is not None and not (window[0] < window[1]):
        raise InputError(f"window start {window[0]:g} s must be before its stop {window[1]:g} s", source=src)
    if not fmt.reports_missing_file and not path.is_file():
        raise InputError("file not found" if not path.exists() else "is not a file", source=src)
    return fmt


def _in_si(
    raw: dict[str, Raw],
    channels: Mapping[str, str],
    units: Mapping[str, str],
    time_unit: str,
    nominal_rate: float | None,
    src: str,
) -> dict[str, float]:
    """Each channel's values and named time vector in SI (in place), its stamps checked (and rebuilt on a nominal
    rate); our name -> its sampling step [s]."""
    steps = {}
    for ours, r in raw.items():
        unit = units.get(ours, r.unit)
        if len(unit) > UNIT_LENGTH:
            raise InputError(
                f"channel '{ours}' ('{channels[ours]}'): its unit is {len(unit)} characters long "
                f"('{clip(unit, 60)}'): not a unit",
                source=src,
            )
        factor = unit_factor(unit, src, f"channel '{ours}' ('{channels[ours]}')")
        with np.errstate(over="ignore", invalid="ignore"):  # a value that overflows is refused by check_channel
            r.y = r.y * factor
            if r.time:
                r.t = r.t * UNITS["time"][time_unit]
        steps[ours] = check_channel(ours, channels[ours], r, src)
        if nominal_rate is not None:
            on_nominal_rate(ours, channels[ours], r, nominal_rate, src)
            steps[ours] = 1.0 / nominal_rate
    return steps


def _windowed(
    t: NDArray, values: dict[str, NDArray], window: tuple[float, float] | None, src: str
) -> tuple[NDArray, dict[str, NDArray]]:
    """The record's times and values within `window` [start, stop) s (all of them without one)."""
    if window is None:
        return t, values
    keep = (t >= window[0]) & (t < window[1])
    if keep.sum() < 3:
        raise InputError(
            f"window [{window[0]:g}, {window[1]:g}) s holds {int(keep.sum())} samples; the record spans "
            f"[0, {t[-1]:g}] s",
            source=src,
        )
    return t[keep], {k: v[keep] for k, v in values.items()}
