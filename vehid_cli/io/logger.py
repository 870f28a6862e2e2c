"""Logger files (issue 13): a recorded run as named channels on one uniform time grid, in SI units.

Vehicle data loggers write ASAM MDF4 (`.mf4`/`.mdf`), test engineers pass on MATLAB files (`.mat`, v5 or the
HDF5-based v7.3), HDF5 (`.h5`/`.hdf5`) and CSV exports (`.csv`/`.txt`, numeric or ISO 8601 time stamps).
`read_record` reads the channels a caller names (our name -> the name in the file), converts them to SI
(`core.units.UNITS`: one unit table for the whole package) and puts them on one uniform grid:

- the grid rate is `rate` when given, else the highest channel rate; the grid spans the time all channels cover;
- a channel sampled faster than the grid (down-sampling) is first low-passed on its own grid with a zero-phase
  Butterworth filter (order 8, `scipy.signal.sosfiltfilt`, cut-off at 40 % of the grid rate, i.e. 80 % of the new
  Nyquist frequency), then interpolated: content above the new Nyquist frequency is removed, not folded back;
- a channel sampled at the grid rate or slower (up-sampling) is interpolated with a cubic spline (not-a-knot);
  samples already on the grid are kept as they are;
- the low-pass starts up over about 2.5 / cut-off seconds at the record's ends (30 ms for a 200 Hz grid): there,
  content above the new Nyquist frequency is not fully removed; cut it with `window` when it matters;
- time stamps that jitter (steps within ±50 % of the median step) are resampled the same way at the median rate;
  a larger step is a gap (a dropped block of samples) and an error, as is a time that goes backwards.

`resample=False` refuses all of this: channels at different rates, jittered stamps or samples off the common grid
are an error, and every value in the Record is a sample of the file. Either way the Record keeps each channel's
own rate and sample times (`Record.rates`, `Record.stamps`), and `Record.native_samples` gives the grid points
that hold a channel's own samples (a 200 Hz channel on a 1 kHz grid: every 5th).

A MAT or HDF5 file holds one time vector for all channels (`t`, `time` or the one named by `time=`), and a channel
`X` sampled otherwise its own beside it: `t_X` (HDF5: in X's group, `acc/t_X` for `acc/X`; see `own_time_name`).
A MAT v5 file may declare its channels' units in a struct `units` (file name -> unit) beside them
(`logger_write.write_record` writes both).

Every problem a user can fix is an `InputError` naming the file and the channel (exit status 2).
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..core.errors import InputError
from ..core.units import UNITS
from .measurement import UNIFORM_TOLERANCE, read_table

SUFFIXES = {
    ".csv": "csv",
    ".txt": "csv",
    ".mf4": "mdf",
    ".mdf": "mdf",
    ".mat": "mat",
    ".h5": "hdf5",
    ".hdf5": "hdf5",
}
TIME_NAMES = ("t", "time", "Time", "TIME", "timestamp", "Timestamp")  # a time column/vector found without `time=`
JITTER = 0.5  # a step within ±50 % of the median step is jitter (resampled); a longer one is a gap (an error)
DOWNSAMPLE_ORDER = 8  # Butterworth order of the anti-alias filter (applied forwards and backwards: zero phase)
DOWNSAMPLE_CUTOFF = 0.4  # its cut-off as a fraction of the new rate (0.8 x the new Nyquist frequency)
RATE_MATCH = 1e-2  # a channel within 1 % of the grid rate is at the grid rate (no filter)
NOMINAL_RATE_MATCH = 0.05  # time stamps printed off a nominal rate: each step within 5 % of 1 / rate
# One unit name -> its factor to SI, over all quantities of core.units.UNITS (no unit name means two things there).
SI_FACTORS: dict[str, float] = {unit: f for table in UNITS.values() for unit, f in table.items()}


NATIVE_MATCH = 1e-3  # a channel's sample within 1e-3 of a grid step of a grid point is on that grid point


@dataclass(frozen=True)
class Record:
    """A recorded run: channels (our names) in SI units on one uniform time grid.

    `rates` and `stamps` keep what the grid hides: a channel's own sampling rate in the file and its own sample
    times, so that a channel up-sampled onto the grid can be compared at its own samples only
    (`native_samples`) rather than at the spline values between them."""

    t: NDArray  # (n,) [s] since the start of the record, uniform
    channels: dict[str, NDArray]  # name -> (n,) values in SI units
    source: str
    rates: dict[str, float]  # name -> its own sampling rate in the file [Hz] (`_rate`; of its time vector)
    # name -> its own sample times [s] on the axis of `t` (the file's stamps less the record's start), those
    # within [t[0], t[-1]] (to 1e-3 of a grid step): after a window, those inside the window
    stamps: dict[str, NDArray]

    @property
    def rate(self) -> float:
        """Sampling rate [Hz]."""
        return float((self.t.size - 1) / (self.t[-1] - self.t[0]))

    def channel(self, name: str) -> NDArray:
        if name not in self.channels:
            raise InputError(
                f"no channel '{name}' in the record{_did_you_mean(name, self.channels)} "
                f"(channels: {', '.join(self.channels)})",
                source=self.source,
            )
        return self.channels[name]

    def native_samples(self, name: str, *, nearest: bool = False) -> NDArray[np.intp]:
        """The grid indices (into `t` and the channel) at which channel `name` was sampled in the file.

        - at the grid rate or faster (within 1 %, `RATE_MATCH`): every index. Every grid point then carries the
          channel, though not always a sample of the file: stamps off the grid were interpolated, and a faster
          channel was low-passed before it was down-sampled (see the module docstring);
        - slower, with every sample within 1e-3 of a step of a grid point (its rate an integer fraction of the grid
          rate, its samples in phase with the grid: a 200 Hz channel on a 1 kHz grid): the indices of those grid
          points, where the values are the file's samples (to round-off; between them they are a cubic spline);
        - slower but off the grid (a rate that does not divide the grid rate, a phase between grid points, or
          jittered stamps): no grid point holds its samples, so this is an InputError, unless `nearest`: then the
          (distinct) grid points nearest to its samples, up to half a step away, where the values are
          interpolated, not sampled; compare at them knowing so.

        After a window the indices refer to the windowed grid."""
        self.channel(name)
        n = self.t.size
        if self.rates[name] >= self.rate * (1 - RATE_MATCH):
            return np.arange(n)
        position = (self.stamps[name] - self.t[0]) * self.rate
        k = np.rint(position)
        off = np.abs(position - k)
        if off.size and float(np.max(off)) > NATIVE_MATCH:
            if not nearest:
                worst = int(np.argmax(off))
                raise InputError(
                    f"channel '{name}' ({self.rates[name]:g} Hz) is not sampled on points of the {self.rate:g} Hz "
                    f"grid: its sample at t = {self.stamps[name][worst]:.9g} s is {off[worst]:.3g} of a step from "
                    f"the nearest; nearest=True gives the nearest grid points (values interpolated there), or read "
                    f"the file at a grid rate its samples fall on",
                    source=self.source,
                )
            return np.unique(np.clip(k, 0, n - 1)).astype(np.intp)
        return k.astype(np.intp)


def _did_you_mean(name: str, known) -> str:
    close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.6)
    if not close:
        lower = {k.lower(): k for k in known}
        close = [lower[name.lower()]] if name.lower() in lower else []
    return f" (did you mean '{close[0]}'?)" if close else ""


def _missing(what: str, name: str, known: Sequence[str], source: str, key: str | None = None) -> InputError:
    return InputError(
        f"{what} '{name}' is not in the file{_did_you_mean(name, known)}; present: {', '.join(known) or 'none'}",
        source=source,
        key=key,
    )


def unit_factor(unit: str, source: str, channel: str) -> float:
    """The factor that turns `unit` into SI ('' is SI); InputError naming the file, the channel and the known units."""
    unit = unit.strip()
    if not unit:
        return 1.0
    if unit in SI_FACTORS:
        return SI_FACTORS[unit]
    raise InputError(
        f"{channel}: unknown unit '{unit}'{_did_you_mean(unit, SI_FACTORS)}; known units: {', '.join(SI_FACTORS)}",
        source=source,
    )


# ------------------------------------------------------------------------------------------ raw channels


@dataclass
class _Raw:
    """One channel as stored: its own time stamps [s], values, and the unit the file declares ('' if none)."""

    t: NDArray
    y: NDArray
    unit: str = ""
    time: str = ""  # the name of its time column/vector ('' for MDF4 masters and stamps made from a rate)


def _numeric(values, source: str, what: str) -> NDArray:
    arr = np.asarray(values)
    if arr.dtype.kind not in "biuf":
        raise InputError(f"{what} is not numeric (type {arr.dtype})", source=source)
    arr = np.squeeze(arr).astype(float)
    if arr.ndim != 1:
        raise InputError(f"{what} has shape {np.shape(values)}; expected a vector", source=source)
    return arr


def _read_csv(path: Path, channels: Mapping[str, str], time: str | None, rate: float | None) -> dict[str, _Raw]:
    candidates = (time,) if time else TIME_NAMES
    table = read_table(path, timestamps=candidates)
    src = table.source
    t, tname = _time_vector(
        time,
        [c for c in candidates if c in table.columns],
        lambda name: table.columns[name],
        list(table.columns),
        src,
        rate,
        n=next(iter(table.columns.values())).size,
    )
    raw = {}
    for ours, theirs in channels.items():
        if theirs not in table.columns:
            raise _missing("column", theirs, list(table.columns), src, key=ours)
        raw[ours] = _Raw(t, table.columns[theirs], time=tname)
    return raw


def _time_vector(time, found, get, names, src, rate, n) -> tuple[NDArray, str]:
    """The time vector named `time`, else the first of `found`, else k / rate ('' for its name); InputError if
    none."""
    if time is not None:
        if time not in names:
            raise _missing("time vector", time, names, src)
        return _numeric(get(time), src, f"time vector '{time}'"), time
    if found:
        return _numeric(get(found[0]), src, f"time vector '{found[0]}'"), found[0]
    if rate is not None:
        return np.arange(n) / rate, ""
    raise InputError(
        f"no time vector ({' or '.join(TIME_NAMES[:2])}): name it with time=..., or give the rate; present: "
        f"{', '.join(names)}",
        source=src,
    )


def _read_mdf(path: Path, channels: Mapping[str, str]) -> dict[str, _Raw]:
    from asammdf import MDF
    from asammdf.blocks.utils import MdfException

    src = str(path)
    try:
        mdf = MDF(path)
    except (MdfException, OSError, ValueError) as exc:
        raise InputError(f"cannot read as ASAM MDF: {exc}", source=src) from None
    try:
        masters = mdf.masters_db
        present = [
            name
            for name, where in mdf.channels_db.items()
            if any(masters.get(g) != i for g, i in where)  # the master (time) channels are not data
        ]
        raw = {}
        for ours, theirs in channels.items():
            if theirs not in present:
                raise _missing("channel", theirs, present, src, key=ours)
            where = [(g, i) for g, i in mdf.channels_db[theirs] if masters.get(g) != i]
            if len(where) > 1:
                groups = ", ".join(str(g) for g, _ in where)
                raise InputError(f"channel '{theirs}' is in several channel groups ({groups})", source=src, key=ours)
            signal = mdf.get(theirs, group=where[0][0], index=where[0][1])
            y = _numeric(signal.samples, src, f"channel '{theirs}'")
            raw[ours] = _Raw(np.asarray(signal.timestamps, dtype=float), y, str(signal.unit or ""))
        return raw
    finally:
        mdf.close()


def _is_hdf5(path: Path) -> bool:
    import h5py

    return h5py.is_hdf5(path)


def _read_mat(
    path: Path, channels: Mapping[str, str], time: str | None, rate: float | None, variable: str | None
) -> dict[str, _Raw]:
    import scipy.io

    src = str(path)
    try:
        mat = scipy.io.loadmat(path, simplify_cells=True)
    except NotImplementedError:  # MATLAB v7.3: an HDF5 file behind a 512-byte MATLAB header
        return _read_hdf5(path, channels, time, rate, variable, matlab=True)
    except (ValueError, OSError, TypeError) as exc:
        if _is_hdf5(path):
            return _read_hdf5(path, channels, time, rate, variable, matlab=True)
        raise InputError(f"cannot read as a MATLAB file: {exc}", source=src) from None
    top = {k: v for k, v in mat.items() if not k.startswith("__")}
    container = _container(top, variable, channels, src)
    return _collect(container, channels, time, rate, src)


def _container(top: dict, variable: str | None, channels: Mapping[str, str], src: str) -> dict:
    """Where the channels are: `variable` (a struct), else the top level, else the one struct at the top level."""
    if variable is not None:
        if variable not in top:
            raise _missing("variable", variable, list(top), src)
        if not isinstance(top[variable], dict):
            raise InputError(f"variable '{variable}' is not a struct of channels", source=src)
        return top[variable]
    structs = [k for k, v in top.items() if isinstance(v, dict)]
    if any(name in top for name in channels.values()) or len(structs) != 1:
        return top
    return top[structs[0]]


def own_time_name(name: str) -> str:
    """The name of the time vector of channel `name` alone in a MAT or HDF5 file: `t_<name>` beside it (HDF5: in
    its group, `acc/t_X` for `acc/X`). A channel without one has the file's common time vector."""
    head, _, leaf = name.strip("/").rpartition("/")
    return f"{head}/t_{leaf}" if head else f"t_{leaf}"


def _stamps_of(channels, names, get, common) -> dict[str, tuple[NDArray, str]]:
    """Each channel's time vector (our name -> stamps, name): its own (`own_time_name`) if the file has one, else
    the common one, `common()`, read only when a channel needs it."""
    stamps, shared = {}, []
    for ours, theirs in channels.items():
        own = own_time_name(theirs)
        if own in names:
            stamps[ours] = get(own), own
        else:
            if not shared:
                shared.append(common())
            stamps[ours] = shared[0]
    return stamps


def _collect(container: dict, channels, time, rate, src) -> dict[str, _Raw]:
    names = list(container)
    first = next(iter(channels.values()), None)
    n = np.size(container[first]) if first in container else 0
    declared = container.get("units") if isinstance(container.get("units"), dict) else {}

    def common():
        found = [c for c in TIME_NAMES if c in container]
        return _time_vector(time, found, container.__getitem__, names, src, rate, n)

    for ours, theirs in channels.items():
        if theirs not in container:
            raise _missing("channel", theirs, names, src, key=ours)
    stamps = _stamps_of(channels, names, lambda k: _numeric(container[k], src, f"time vector '{k}'"), common)
    raw = {}
    for ours, theirs in channels.items():
        t, tname = stamps[ours]
        y = _numeric(container[theirs], src, f"channel '{theirs}'")
        raw[ours] = _Raw(t, y, str(declared.get(theirs, "")), time=tname)
    return raw


def _read_hdf5(path, channels, time, rate, variable, matlab: bool = False) -> dict[str, _Raw]:
    """Datasets by path (relative to the group `variable`, or the root). MATLAB v7.3 stores arrays transposed;
    vectors (all a channel can be) read the same either way. A dataset's `unit` or `units` attribute is its unit."""
    import h5py

    src = str(path)
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise InputError(f"cannot read as HDF5{' (MATLAB v7.3)' if matlab else ''}: {exc}", source=src) from None
    with f:
        group = f
        if variable is not None:
            if variable not in f or not isinstance(f[variable], h5py.Group):
                tops = [k for k in f if not k.startswith("#")]  # '#refs#': MATLAB's internal references
                if variable in f:
                    raise InputError(f"variable '{variable}' is not a struct (HDF5 group) of channels", source=src)
                raise _missing("variable", variable, tops, src)
            group = f[variable]
        elif matlab:
            tops = [k for k in f if not k.startswith("#")]
            structs = [k for k in tops if isinstance(f[k], h5py.Group)]
            if not any(name in f for name in channels.values()) and len(structs) == 1:
                group = f[structs[0]]

        datasets: list[str] = []
        group.visititems(lambda name, obj: datasets.append(name) if isinstance(obj, h5py.Dataset) else None)

        def get(name: str) -> NDArray:
            return group[name][()]

        def unit(name: str) -> str:
            attrs = group[name].attrs
            value = attrs.get("unit", attrs.get("units", ""))
            return value.decode() if isinstance(value, bytes) else str(value)

        first = next(iter(channels.values()), None)
        n = group[first].size if first in datasets else 0

        def common():
            found = [c for c in TIME_NAMES if c in datasets]
            return _time_vector(time, found, get, datasets, src, rate, n)

        keys = {ours: theirs.strip("/") for ours, theirs in channels.items()}
        for ours, theirs in channels.items():
            if keys[ours] not in datasets:
                raise _missing("dataset" if not matlab else "channel", theirs, datasets, src, key=ours)
        stamps = _stamps_of(keys, datasets, lambda k: _numeric(get(k), src, f"time vector '{k}'"), common)
        raw = {}
        for ours, theirs in channels.items():
            t, tname = stamps[ours]
            raw[ours] = _Raw(t, _numeric(get(keys[ours]), src, f"channel '{theirs}'"), unit(keys[ours]), time=tname)
        return raw


# ------------------------------------------------------------------------------------------ one grid


def _named(time: str, before: str = "") -> str:
    """ " '<time column>'" (after `before`) when the stamps come from a named column/vector, else ''."""
    return f"{before} '{time}'" if time else ""


class NominalRateError(InputError):
    """Time stamps that do not follow the nominal rate given to `read_record` (callers may name their key)."""


def _worst_step(steps: NDArray, dt: float) -> int:
    """The index of the time step furthest from dt [s]: what the nominal-rate check (5 %) and the gap check (50 %)
    each judge against their own tolerance."""
    return int(np.argmax(np.abs(steps - dt)))


def _on_nominal_rate(name: str, theirs: str, raw: _Raw, rate: float, src: str) -> None:
    """Printed time stamps rounded off a nominal rate: check every step is within 5 % of 1 / rate, then rebuild
    the stamps as t0 + k / rate (the samples are kept as they are, not resampled)."""
    dt = 1.0 / rate
    steps = np.diff(raw.t)
    bad = _worst_step(steps, dt)
    if abs(steps[bad] - dt) > NOMINAL_RATE_MATCH * dt:
        raise NominalRateError(
            f"channel '{name}' ('{theirs}'): time{_named(raw.time)} does not follow the nominal rate {rate:g} Hz "
            f"(step {dt:g} s) within {NOMINAL_RATE_MATCH:.0%}: step {steps[bad]:g} s at sample {bad + 2}",
            source=src,
        )
    raw.t = raw.t[0] + np.arange(raw.t.size) * dt


def _check_channel(name: str, theirs: str, raw: _Raw, src: str) -> float:
    """Check a channel's stamps and values; return its (median) sampling step [s]."""
    label = f"channel '{name}' ('{theirs}')"
    if raw.t.size != raw.y.size:
        raise InputError(f"{label} has {raw.y.size} samples but its time vector {raw.t.size}", source=src)
    if raw.y.size < 3:
        raise InputError(f"{label} has {raw.y.size} samples; at least 3 are needed", source=src)
    for what, values in (("time stamp", raw.t), ("sample", raw.y)):
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise InputError(
                f"{label} has {bad.size} non-finite {what}(s){_named(raw.time, ' in') if what[0] == 't' else ''} "
                f"(NaN or Inf), first at sample {bad[0] + 1}",
                source=src,
            )
    steps = np.diff(raw.t)
    if np.any(steps <= 0):
        k = int(np.flatnonzero(steps <= 0)[0])
        raise InputError(
            f"{label}: time{_named(raw.time)} goes backwards (or stands still), it must increase strictly: at "
            f"sample {k + 2}, t = {raw.t[k + 1]:.9g} s after {raw.t[k]:.9g} s",
            source=src,
        )
    dt = float(np.median(steps))
    worst = _worst_step(steps, dt)
    if abs(steps[worst] - dt) > JITTER * dt:
        raise InputError(
            f"{label}: a gap in time at sample {worst + 2}: step {steps[worst]:.6g} s against the usual {dt:.6g} s "
            f"(dropped samples?); cut the record with a window",
            source=src,
        )
    return dt


def _uniform(t: NDArray, dt: float) -> bool:
    return bool(np.max(np.abs(np.diff(t) - dt)) <= max(UNIFORM_TOLERANCE * dt, 1e-9 * float(np.max(np.abs(t)))))


def _rate(raw: _Raw, dt: float) -> float:
    """A channel's rate [Hz]: from its span when uniform, else its median step; to 9 significant digits (a logger's
    nominal rate, not the round-off of its time stamps: 1/0.0010000000000000002 s is 1000 Hz)."""
    rate = (raw.t.size - 1) / float(raw.t[-1] - raw.t[0]) if _uniform(raw.t, dt) else 1.0 / dt
    return float(f"{rate:.9g}")


def _grid_slice(raw: _Raw, dt: float, grid: NDArray) -> slice | None:
    """The run of the channel's samples that lies on the grid (each stamp within UNIFORM_TOLERANCE of a step of
    its grid point), None if there is none: the channel is then resampled."""
    first = int(round((grid[0] - raw.t[0]) / dt))
    keep = slice(first, first + grid.size)
    if first < 0 or keep.stop > raw.t.size:
        return None
    return keep if np.allclose(raw.t[keep], grid, rtol=0, atol=UNIFORM_TOLERANCE * dt) else None


def _onto(raw: _Raw, dt: float, grid: NDArray, rate: float) -> NDArray:
    """A channel on the grid: its own samples when they lie on the grid (`_grid_slice`); else an anti-alias
    low-pass first when its rate is above the grid's, then a cubic spline."""
    from scipy.interpolate import CubicSpline
    from scipy.signal import butter, sosfiltfilt

    t, y = raw.t, raw.y
    own = 1.0 / dt
    if own <= rate * (1 + RATE_MATCH) and (keep := _grid_slice(raw, dt, grid)) is not None:
        return y[keep].copy()
    if own > rate * (1 + RATE_MATCH):
        if not _uniform(t, dt):  # filter on a uniform grid: resample the jittered stamps at their median rate first
            tu = t[0] + np.arange(int(math.floor((t[-1] - t[0]) / dt + 1e-9)) + 1) * dt
            y, t = CubicSpline(t, y)(tu), tu
        sos = butter(DOWNSAMPLE_ORDER, DOWNSAMPLE_CUTOFF * rate, fs=own, output="sos")
        y = sosfiltfilt(sos, y)
    return CubicSpline(t, y)(grid)


RESAMPLE_HINT = "allow resampling to read it (resample=True; config key data.resample)"


def _refuse_resampling(raw, channels, steps, rates, rate, src) -> None:
    """`resample=False`: every channel uniform and at one rate (within RATE_MATCH), that of `rate` if given."""
    for ours, r in raw.items():
        if not _uniform(r.t, steps[ours]):
            steps_ = np.diff(r.t)
            raise InputError(
                f"channel '{ours}' ('{channels[ours]}'): time stamps{_named(r.time, ' in')} jitter (steps "
                f"{steps_.min():.6g} to {steps_.max():.6g} s about the median {steps[ours]:.6g} s): reading them "
                f"means resampling at the median rate; {RESAMPLE_HINT}",
                source=src,
            )
    reference = rate if rate is not None else max(rates.values())
    if any(abs(f - reference) > RATE_MATCH * reference for f in rates.values()):
        listed = ", ".join(f"'{ours}' ('{channels[ours]}') {f:g} Hz" for ours, f in rates.items())
        what = f"differ from the grid rate {rate:g} Hz" if rate is not None else "differ"
        raise InputError(
            f"the channels' rates {what}: {listed}; one grid for them means resampling; {RESAMPLE_HINT}",
            source=src,
        )


def _refuse_off_grid(ours: str, theirs: str, raw: _Raw, dt: float, grid: NDArray, src: str) -> None:
    """`resample=False`: a channel at the grid rate whose samples are not on the common grid (a phase between
    grid points, or a rate within 1 % of the grid's that drifts off it)."""
    if _grid_slice(raw, dt, grid) is None:
        k = int(np.argmin(np.abs(raw.t - grid[0])))
        raise InputError(
            f"channel '{ours}' ('{theirs}'): its samples are not on the common grid ({grid.size} samples from "
            f"{grid[0]:.9g} s at {1 / (grid[1] - grid[0]):g} Hz; its nearest sample to the start is at "
            f"{raw.t[k]:.9g} s, its step {dt:.9g} s): reading it means resampling; {RESAMPLE_HINT}",
            source=src,
        )


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

    The format is the suffix's (module docstring). `units` gives a channel's unit (our name -> unit, e.g. 'g',
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
    kind = SUFFIXES.get(path.suffix.lower())
    if kind is None:
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
            f"unknown time unit '{time_unit}'{_did_you_mean(time_unit, UNITS['time'])}; known: "
            f"{', '.join(UNITS['time'])}",
            source=src,
        )
    if window is not None and not (window[0] < window[1]):
        raise InputError(f"window start {window[0]:g} s must be before its stop {window[1]:g} s", source=src)
    if kind != "csv" and not path.is_file():
        raise InputError("file not found" if not path.exists() else "is not a file", source=src)

    if kind == "csv":
        raw = _read_csv(path, channels, time, rate)
    elif kind == "mdf":
        raw = _read_mdf(path, channels)
    elif kind == "mat":
        raw = _read_mat(path, channels, time, rate, variable)
    else:
        raw = _read_hdf5(path, channels, time, rate, variable)

    steps = {}
    for ours, r in raw.items():
        unit = units.get(ours, r.unit)
        r.y = r.y * unit_factor(unit, src, f"channel '{ours}' ('{channels[ours]}')")
        if r.time:
            r.t = r.t * UNITS["time"][time_unit]
        steps[ours] = _check_channel(ours, channels[ours], r, src)
        if nominal_rate is not None:
            _on_nominal_rate(ours, channels[ours], r, nominal_rate, src)
            steps[ours] = 1.0 / nominal_rate

    rates = {ours: _rate(r, steps[ours]) for ours, r in raw.items()}
    if not resample:
        _refuse_resampling(raw, channels, steps, rates, rate, src)
    grid_rate = rate if rate is not None else max(rates.values())
    start = max(float(r.t[0]) for r in raw.values())
    stop = min(float(r.t[-1]) for r in raw.values())
    n = int(math.floor((stop - start) * grid_rate + 1e-6)) + 1  # 1e-6: a sample at `stop` despite round-off
    if stop <= start or n < 3:
        raise InputError(
            f"the channels ({', '.join(channels)}) share no common time span of 3 samples at {grid_rate:g} Hz",
            source=src,
        )
    grid = start + np.arange(n) / grid_rate
    if not resample:
        for ours, r in raw.items():
            _refuse_off_grid(ours, channels[ours], r, steps[ours], grid, src)
    values = {ours: _onto(r, steps[ours], grid, grid_rate) for ours, r in raw.items()}
    t = np.arange(n) / grid_rate
    if window is not None:
        keep = (t >= window[0]) & (t < window[1])
        if keep.sum() < 3:
            raise InputError(
                f"window [{window[0]:g}, {window[1]:g}) s holds {int(keep.sum())} samples; the record spans "
                f"[0, {t[-1]:g}] s",
                source=src,
            )
        t = t[keep]
        values = {k: v[keep] for k, v in values.items()}
    near = NATIVE_MATCH / grid_rate
    stamps = {ours: r.t - start for ours, r in raw.items()}
    stamps = {ours: s[(s >= t[0] - near) & (s <= t[-1] + near)] for ours, s in stamps.items()}
    return Record(t=t, channels=values, source=src, rates=rates, stamps=stamps)


def remove_offset(record: Record, names: Sequence[str], mode: str = "mean") -> Record:
    """The record with the named channels' offsets removed: their mean over the whole record (`mean`) or over
    its first second (`first_second`: the car at rest before the run), e.g. accelerometers' gravity and bias."""
    if mode not in ("mean", "first_second"):
        raise InputError(f"unknown offset mode '{mode}'; expected mean or first_second", source=record.source)
    keep = slice(None)
    if mode == "first_second":
        keep = record.t < record.t[0] + 1.0
        if record.t[-1] - record.t[0] < 1.0:
            raise InputError(
                f"the record lasts {record.t[-1] - record.t[0]:g} s, less than one second", source=record.source
            )
    channels = dict(record.channels)
    for name in names:
        y = record.channel(name)
        channels[name] = y - float(np.mean(y[keep]))
    return replace(record, channels=channels)
