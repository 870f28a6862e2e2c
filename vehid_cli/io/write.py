"""Writing logger files (issue 13): a run of named channels, each with its own time stamps, in the formats
`io.read.read_record` reads, so that synthetic runs and converted files go the same way as a logger's.

The format is the suffix's (`io.formats`, one module each: `.mf4` ASAM MDF 4.10, `.mat` MATLAB v5, `.h5`/`.hdf5`
HDF5, `.csv`/`.txt` CSV at one rate). Values are given in SI units and written in the unit named for the channel
(written = SI / factor, the factor of `core.units.unit_factor`; default SI). Every write is atomic
(`core.files.atomic_path`): the target holds its old content or the whole new file (HDF5: built in memory,
`core.store.h5_file`).
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..core.errors import InputError
from ..core.units import unit_factor
from .formats import FORMATS, LoggerFormat, writable


def write_record(
    path: str | Path,
    channels: Mapping[str, tuple[NDArray, NDArray]],
    *,
    units: Mapping[str, str] | None = None,
    names: Mapping[str, str] | None = None,
    start: dt.datetime | None = None,
    comment: str = "",
) -> Path:
    """Write a run to `path` in the format of its suffix (module docstring); return the path.

    `channels`: our name -> (t [s], values in SI units), each channel with its own strictly increasing time stamps
    (a rate of its own). `units`: our name -> the unit it is written in (`core.units.UNITS`, e.g. 'g', 'mm'; default
    SI). `names`: our name -> its name in the file (default ours). `start`: the wall-clock time of t = 0 (MDF4
    header, an attribute, a variable or a comment line). Bad input is an InputError naming the file and the
    channel (our name and the file's)."""
    path = Path(path)
    src = str(path)
    units = dict(units or {})
    names = dict(names or {})
    fmt = _format_of(path, channels, units, names)
    theirs = _file_names(channels, names, src)
    runs = _runs(channels, theirs, units, src)
    written = {ours: units.get(ours, "").strip() for ours in channels}
    fmt.write(path, runs, theirs, written, start=start, comment=comment)
    return path


def _format_of(
    path: Path, channels: Mapping[str, object], units: Mapping[str, str], names: Mapping[str, str]
) -> LoggerFormat:
    """The format that writes the path's suffix, once the channels, units and names given are checked."""
    src = str(path)
    suffix = path.suffix.lower()
    fmt = FORMATS.get(suffix)
    if fmt is None or suffix not in fmt.writes:
        raise InputError(
            f"cannot write a logger file of type '{path.suffix}'; write one of {', '.join(writable())}", source=src
        )
    if not channels:
        raise InputError("no channels to write", source=src)
    for what, given in (("unit", units), ("name", names)):
        for ours in given:
            if ours not in channels:
                raise InputError(
                    f"a {what} is given for '{ours}', which is not a channel written ({', '.join(channels)})",
                    source=src,
                )
    return fmt


def _file_names(channels: Mapping[str, object], names: Mapping[str, str], src: str) -> dict[str, str]:
    """Our name -> its name in the file (default ours); InputError for an empty name or one given twice."""
    theirs = {ours: str(names.get(ours, ours)) for ours in channels}
    for ours, name in theirs.items():
        if not name.strip():
            raise InputError(f"channel '{ours}' has an empty name in the file", source=src)
    clash = sorted({n for n in theirs.values() if list(theirs.values()).count(n) > 1})
    if clash:
        raise InputError(f"several channels are named {', '.join(map(repr, clash))} in the file", source=src)
    return theirs


def _runs(
    channels: Mapping[str, tuple[NDArray, NDArray]], theirs: Mapping[str, str], units: Mapping[str, str], src: str
) -> dict[str, tuple[NDArray, NDArray]]:
    """Our name -> (t [s], values in the unit written), each checked: numeric vectors of one length, stamps finite
    and strictly increasing."""
    runs: dict[str, tuple[NDArray, NDArray]] = {}
    for ours, pair in channels.items():
        label = f"channel '{ours}' ('{theirs[ours]}')"
        t, y = _vector(pair[0], src, f"{label}: time"), _vector(pair[1], src, f"{label}: values")
        if t.size != y.size:
            raise InputError(f"{label} has {y.size} values but {t.size} time stamps", source=src)
        if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
            raise InputError(f"{label}: time stamps must be finite and increase strictly", source=src)
        runs[ours] = t, y / unit_factor(units.get(ours, ""), src, label)
    return runs


def _vector(values, src: str, what: str) -> NDArray:
    arr = np.asarray(values)
    if arr.dtype.kind not in "biuf" or arr.ndim != 1 or arr.size == 0:
        raise InputError(f"{what} must be a non-empty numeric vector (got {arr.dtype}, shape {arr.shape})", source=src)
    return arr.astype(float)
