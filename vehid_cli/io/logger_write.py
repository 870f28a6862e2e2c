"""Writing logger files (issue 13): a run of named channels, each with its own time stamps, in the formats
`logger.read_record` reads, so that synthetic runs and converted files go the same way as a logger's.

The format is the suffix's:

- `.mf4`: ASAM MDF 4.10 (asammdf); channels with the same time stamps share a channel group (its master is their
  time), each channel with its unit; `start` is the header's start time, `comment` the header comment;
- `.mat`: MATLAB v5 (`scipy.io.savemat`), column vectors at the top level: `t` [s], the stamps of the channels
  at the highest rate (the first such channel's), each channel under its file name, a channel sampled otherwise
  with its own time vector `t_<name>` beside it (`logger.own_time_name`), a struct `units` (file name -> unit),
  and the char arrays `comment` and `start` (ISO 8601) when given. File names must be MATLAB names (a letter,
  then letters, digits and '_'; at most 63 characters, `t_<name>` included);
- `.h5`/`.hdf5`: HDF5 (h5py), the same layout with datasets by path (`acc/X`: a dataset X in group acc, its own
  time vector `acc/t_X`), each with a `unit` attribute ('s' for time vectors); `comment` and `start` are
  attributes of the root;
- `.csv`/`.txt`: one time column `t` [s] and the channels, numbers to 17 significant digits (they read back
  exactly); `#` lines before the header hold the comment, the start and the units for people, but `read_record`
  reads no units from a CSV: pass them (`units=`). One rate only: channels with different time stamps are an
  InputError.

Values are given in SI units and written in the unit named for the channel (written = SI / factor, the factor
of `logger.unit_factor`; default SI). Every write is atomic (`data.atomic_path`): the target holds its old
content or the whole new file (HDF5: built in memory, `h5io.h5_file`).
"""

from __future__ import annotations

import datetime as dt
import re
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..core.errors import InputError
from ..core.files import atomic_path
from ..core.h5file import h5_file
from .logger import SUFFIXES, own_time_name, unit_factor

MATLAB_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
MATLAB_NAME_LENGTH = 63  # namelengthmax
CSV_FORBIDDEN = (",", ";", "\t", "\n", "\r")  # read_table's separators and line ends


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
    kind = SUFFIXES.get(path.suffix.lower())
    if kind is None or path.suffix.lower() == ".mdf":
        writable = ", ".join(s for s in SUFFIXES if s != ".mdf")
        raise InputError(f"cannot write a logger file of type '{path.suffix}'; write one of {writable}", source=src)
    if not channels:
        raise InputError("no channels to write", source=src)
    for what, given in (("unit", units), ("name", names)):
        for ours in given:
            if ours not in channels:
                raise InputError(
                    f"a {what} is given for '{ours}', which is not a channel written ({', '.join(channels)})",
                    source=src,
                )
    theirs = {ours: str(names.get(ours, ours)) for ours in channels}
    for ours, name in theirs.items():
        if not name.strip():
            raise InputError(f"channel '{ours}' has an empty name in the file", source=src)
    clash = sorted({n for n in theirs.values() if list(theirs.values()).count(n) > 1})
    if clash:
        raise InputError(f"several channels are named {', '.join(map(repr, clash))} in the file", source=src)

    runs: dict[str, tuple[NDArray, NDArray]] = {}
    for ours, pair in channels.items():
        label = f"channel '{ours}' ('{theirs[ours]}')"
        t, y = _vector(pair[0], src, f"{label}: time"), _vector(pair[1], src, f"{label}: values")
        if t.size != y.size:
            raise InputError(f"{label} has {y.size} values but {t.size} time stamps", source=src)
        if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
            raise InputError(f"{label}: time stamps must be finite and increase strictly", source=src)
        runs[ours] = t, y / unit_factor(units.get(ours, ""), src, label)
    written = {ours: units.get(ours, "").strip() for ours in channels}

    if kind == "hdf5":  # built in memory, its bytes written atomically (h5io: HDF5 locks a file it writes)
        _write_hdf5(path, runs, theirs, written, start, comment, src)
        return path
    with atomic_path(path) as tmp:
        if kind == "mdf":
            _write_mdf(tmp, runs, theirs, written, start, comment)
        elif kind == "mat":
            _write_mat(tmp, runs, theirs, written, start, comment, src)
        else:
            _write_csv(tmp, runs, theirs, written, start, comment, src)
    return path


def _vector(values, src: str, what: str) -> NDArray:
    arr = np.asarray(values)
    if arr.dtype.kind not in "biuf" or arr.ndim != 1 or arr.size == 0:
        raise InputError(f"{what} must be a non-empty numeric vector (got {arr.dtype}, shape {arr.shape})", source=src)
    return arr.astype(float)


def _groups(runs: Mapping[str, tuple[NDArray, NDArray]]) -> list[tuple[NDArray, list[str]]]:
    """Channels by their time stamps (identical arrays share a group), in the order first met."""
    groups: list[tuple[NDArray, list[str]]] = []
    for ours, (t, _) in runs.items():
        for stamps, members in groups:
            if np.array_equal(stamps, t):
                members.append(ours)
                break
        else:
            groups.append((t, [ours]))
    return groups


def _common(runs) -> tuple[NDArray, list[str]]:
    """The group whose stamps the common time vector `t` holds: the highest rate (the first such group)."""
    groups = _groups(runs)

    def rate(group):
        t = group[0]
        return (t.size - 1) / (t[-1] - t[0]) if t.size > 1 else 0.0

    return max(groups, key=rate)  # max keeps the first of equals


def _layout(runs, theirs, src: str, fmt: str, reserved: set[str]) -> tuple[NDArray, dict[str, str]]:
    """MAT/HDF5: the common time vector and, for each channel not sampled at its stamps, its own time vector's
    name; InputError if a name written twice."""
    t, shared = _common(runs)
    own = {ours: own_time_name(theirs[ours]) for ours in runs if ours not in shared}
    taken: dict[str, str] = {n: f"the {fmt} file's '{n}'" for n in reserved}
    for ours in runs:
        for name, what in ((theirs[ours], f"channel '{ours}'"), (own.get(ours), f"the time vector of '{ours}'")):
            if name is None:
                continue
            key = name.strip("/")
            if key in taken:
                raise InputError(f"{what} would be written as '{name}', as is {taken[key]}", source=src)
            taken[key] = what
    return t, own


def _write_mdf(tmp: Path, runs, theirs, units, start, comment) -> None:
    from asammdf import MDF, Signal

    mdf = MDF(version="4.10")
    try:
        if start is not None:
            mdf.header.start_time = start
        if comment:
            mdf.header.comment = comment
        for t, members in _groups(runs):
            rate = (t.size - 1) / (t[-1] - t[0]) if t.size > 1 else 0.0
            signals = [Signal(runs[o][1], t, name=theirs[o], unit=units[o]) for o in members]
            mdf.append(signals, comment=f"{rate:.9g} Hz")
        with open(tmp, "wb+") as fh:  # a file object: asammdf renames a path to '.mf4'
            mdf.save(fh, overwrite=True)
    finally:
        mdf.close()


def _write_mat(tmp: Path, runs, theirs, units, start, comment, src) -> None:
    import scipy.io

    for ours, name in theirs.items():
        longest = len(own_time_name(name))
        if not MATLAB_NAME.fullmatch(name) or longest > MATLAB_NAME_LENGTH:
            raise InputError(
                f"channel '{ours}': '{name}' is not a MATLAB name (a letter, then letters, digits and '_'; with "
                f"its time vector '{own_time_name(name)}' at most {MATLAB_NAME_LENGTH} characters)",
                source=src,
            )
    reserved = {"t", "units"} | ({"comment"} if comment else set()) | ({"start"} if start is not None else set())
    t, own = _layout(runs, theirs, src, "MAT", reserved)
    variables: dict[str, object] = {"t": t}
    for ours, (stamps, y) in runs.items():
        variables[theirs[ours]] = y
        if ours in own:
            variables[own[ours]] = stamps
    variables["units"] = {theirs[ours]: units[ours] for ours in runs}
    if comment:
        variables["comment"] = comment
    if start is not None:
        variables["start"] = start.isoformat()
    with open(tmp, "wb") as fh:  # a file object: savemat would append '.mat' to the temporary's name
        scipy.io.savemat(fh, variables, oned_as="column")


def _write_hdf5(path: Path, runs, theirs, units, start, comment, src) -> None:
    for ours, name in theirs.items():
        parts = name.strip("/").split("/")
        if any(not p.strip() for p in parts):
            raise InputError(f"channel '{ours}': '{name}' has an empty part in its HDF5 path", source=src)
        for k in range(1, len(parts)):  # a group on the path may not be a dataset written
            group = "/".join(parts[:k])
            if group in {n.strip("/") for n in theirs.values()} | {"t"}:
                raise InputError(f"channel '{ours}': '{name}' needs a group '{group}', a channel's name", source=src)
    t, own = _layout(runs, theirs, src, "HDF5", {"t"})
    with h5_file(path) as f:
        if comment:
            f.attrs["comment"] = comment
        if start is not None:
            f.attrs["start"] = start.isoformat()
        f.create_dataset("t", data=t).attrs["unit"] = "s"
        for ours, (stamps, y) in runs.items():
            f.create_dataset(theirs[ours].strip("/"), data=y).attrs["unit"] = units[ours]
            if ours in own:
                f.create_dataset(own[ours], data=stamps).attrs["unit"] = "s"


def _write_csv(tmp: Path, runs, theirs, units, start, comment, src) -> None:
    groups = _groups(runs)
    if len(groups) > 1:
        listed = "; ".join(
            ", ".join(f"'{o}' ('{theirs[o]}')" for o in members) + f": {t.size} stamps from {t[0]:.9g} s"
            for t, members in groups
        )
        raise InputError(
            f"a CSV file has one time column, but the channels have different time stamps ({listed}): write them "
            f"to .mf4, .mat or .h5, or resample them onto one grid first",
            source=src,
        )
    for ours, name in theirs.items():
        if any(c in name for c in CSV_FORBIDDEN) or name != name.strip() or name.startswith("#") or name == "t":
            raise InputError(
                f"channel '{ours}': '{name}' cannot be a CSV column name (no separator, line end, surrounding "
                f"space, leading '#', and not 't', the time column)",
                source=src,
            )
    t = groups[0][0]
    head = [f"# {line}" for line in comment.splitlines()]
    if start is not None:
        head.append(f"# start: {start.isoformat()}")
    head.append("# units: " + ", ".join(f"{theirs[o]} [{units[o] or 'SI'}]" for o in runs) + " (t [s])")
    table = np.column_stack([t] + [runs[o][1] for o in runs])
    with open(tmp, "w", encoding="utf-8", newline="\n") as fh:
        fh.write("\n".join(head) + "\n" + ",".join(["t", *theirs.values()]) + "\n")
        np.savetxt(fh, table, fmt="%.17g", delimiter=",")
