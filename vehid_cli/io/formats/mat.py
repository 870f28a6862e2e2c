"""MATLAB files (`.mat`), as test engineers pass logger runs on: v5 read and written with scipy.io, v7.3 (an HDF5
file behind a 512-byte MATLAB header) read as HDF5 (`hdf5.read_hdf5`).

Reading: the channels are variables at the top level, or fields of the struct `variable` (else of the one struct
at the top level when no channel is there); the common time vector is `t` or `time` (or the one named by
`time=`), a channel sampled otherwise has its own beside it, `t_<name>` (`base.own_time_name`). A v5 file may
declare its channels' units in a struct `units` (file name -> unit) beside them.

Writing (MATLAB v5, `scipy.io.savemat`): column vectors at the top level: `t` [s], the stamps of the channels at
the highest rate (the first such channel's), each channel under its file name, a channel sampled otherwise with
its own time vector `t_<name>` beside it, a struct `units` (file name -> unit), and the char arrays `comment` and
`start` (ISO 8601) when given. File names must be MATLAB names (a letter, then letters, digits and '_'; at most
63 characters, `t_<name>` included).
"""

from __future__ import annotations

import datetime as dt
import re
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ...core.errors import InputError
from ...core.files import atomic_path
from ...core.isolated import Damaged, in_child
from .base import (
    TIME_NAMES,
    LoggerFormat,
    Raw,
    layout,
    missing,
    numeric,
    own_time_name,
    register,
    stamps_of,
    time_vector,
)
from .hdf5 import read_hdf5

MATLAB_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
MATLAB_NAME_LENGTH = 63  # namelengthmax


@register
class Mat(LoggerFormat):
    """MATLAB v5 and v7.3 (module docstring)."""

    name = "mat"
    suffixes = (".mat",)
    writes = (".mat",)
    rank = 30

    def read(
        self, path: Path, channels: Mapping[str, str], *, time: str | None, rate: float | None, variable: str | None
    ) -> dict[str, Raw]:
        src = str(path)
        if _is_hdf5(path):  # MATLAB v7.3: an HDF5 file behind a 512-byte MATLAB header
            return read_hdf5(path, channels, time, rate, variable, matlab=True)
        size = path.stat().st_size
        try:  # scipy.io.loadmat can crash the process on a damaged header: it reads in a child (core.isolated)
            mat = in_child(_load_v5, src, size=size)
        except Damaged as exc:
            raise InputError(f"cannot read as a MATLAB file (damaged, or not one): {exc.reason}", source=src) from None
        if mat is None:  # the header says v7.3, but no HDF5 file follows it
            raise InputError("cannot read as a MATLAB file: its header says v7.3 (HDF5), but it holds no HDF5 file",
                             source=src)  # fmt: skip
        top = {k: v for k, v in mat.items() if not k.startswith("__")}
        container = _container(top, variable, channels, src)
        return _collect(container, channels, time, rate, src)

    def write(
        self,
        path: Path,
        runs: Mapping[str, tuple[NDArray, NDArray]],
        names: Mapping[str, str],
        units: Mapping[str, str],
        *,
        start: dt.datetime | None,
        comment: str,
    ) -> None:
        with atomic_path(path) as tmp:
            _write_mat(tmp, runs, names, units, start, comment, str(path))


def _is_hdf5(path: Path) -> bool:
    import h5py

    try:
        return bool(h5py.is_hdf5(path))
    except (OSError, ValueError):
        return False


def _load_v5(src: str) -> dict | None:
    """In the child: the variables of a MAT v5 file (None when its header says v7.3)."""
    import scipy.io

    try:
        return scipy.io.loadmat(src, simplify_cells=True)
    except NotImplementedError:  # MATLAB v7.3 in the header
        return None


def _container(top: dict, variable: str | None, channels: Mapping[str, str], src: str) -> dict:
    """Where the channels are: `variable` (a struct), else the top level, else the one struct at the top level."""
    if variable is not None:
        if variable not in top:
            raise missing("variable", variable, list(top), src)
        if not isinstance(top[variable], dict):
            raise InputError(f"variable '{variable}' is not a struct of channels", source=src)
        return top[variable]
    structs = [k for k, v in top.items() if isinstance(v, dict)]
    if any(name in top for name in channels.values()) or len(structs) != 1:
        return top
    return top[structs[0]]


def _collect(container: dict, channels, time, rate, src) -> dict[str, Raw]:
    names = list(container)
    first = next(iter(channels.values()), None)
    n = np.size(container[first]) if first in container else 0
    declared = container.get("units") if isinstance(container.get("units"), dict) else {}

    def common():
        found = [c for c in TIME_NAMES if c in container]
        return time_vector(time, found, container.__getitem__, names, src, rate, n)

    for ours, theirs in channels.items():
        if theirs not in container:
            raise missing("channel", theirs, names, src, key=ours)
    stamps = stamps_of(channels, names, lambda k: numeric(container[k], src, f"time vector '{k}'"), common)
    raw = {}
    for ours, theirs in channels.items():
        t, tname = stamps[ours]
        y = numeric(container[theirs], src, f"channel '{theirs}'")
        raw[ours] = Raw(t, y, str(declared.get(theirs, "")), time=tname)
    return raw


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
    t, own = layout(runs, theirs, src, "MAT", reserved)
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
