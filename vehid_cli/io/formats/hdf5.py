"""HDF5 (`.h5`/`.hdf5`) logger files, read and written with h5py; also the reader of MATLAB v7.3 files (`mat.py`).

Channels are datasets by path (`acc/X`: a dataset X in group acc), relative to the group `variable` or the root;
the common time vector is `t` or `time` (or the one named by `time=`), a channel sampled otherwise has its own
beside it (`acc/t_X`, `base.own_time_name`). A dataset's `unit` (or `units`) attribute is its unit.

Writing: the same layout, each dataset with a `unit` attribute ('s' for time vectors); `comment` and `start` are
attributes of the root. The file is built in memory and its bytes written atomically (`core.store.h5_file`: HDF5
locks a file it writes).
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ...core.errors import InputError, clip
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


@register
class Hdf5(LoggerFormat):
    """HDF5 through h5py (module docstring)."""

    name = "hdf5"
    suffixes = (".h5", ".hdf5")
    writes = (".h5", ".hdf5")
    rank = 40

    def read(
        self, path: Path, channels: Mapping[str, str], *, time: str | None, rate: float | None, variable: str | None
    ) -> dict[str, Raw]:
        return read_hdf5(path, channels, time, rate, variable)

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
        from ...core.store import h5_file

        src = str(path)
        for ours, name in names.items():
            parts = name.strip("/").split("/")
            if any(not p.strip() for p in parts):
                raise InputError(f"channel '{ours}': '{name}' has an empty part in its HDF5 path", source=src)
            for k in range(1, len(parts)):  # a group on the path may not be a dataset written
                group = "/".join(parts[:k])
                if group in {n.strip("/") for n in names.values()} | {"t"}:
                    raise InputError(
                        f"channel '{ours}': '{name}' needs a group '{group}', a channel's name", source=src
                    )
        t, own = layout(runs, names, src, "HDF5", {"t"})
        with h5_file(path) as f:
            if comment:
                f.attrs["comment"] = comment
            if start is not None:
                f.attrs["start"] = start.isoformat()
            f.create_dataset("t", data=t).attrs["unit"] = "s"
            for ours, (stamps, y) in runs.items():
                f.create_dataset(names[ours].strip("/"), data=y).attrs["unit"] = units[ours]
                if ours in own:
                    f.create_dataset(own[ours], data=stamps).attrs["unit"] = "s"


def _text(name: str | bytes) -> str:
    """A dataset's name as text: h5py gives bytes for a name that is not UTF-8 (a damaged file's), shown escaped."""
    return name if isinstance(name, str) else name.decode("utf-8", "backslashreplace")


def read_hdf5(
    path: Path,
    channels: Mapping[str, str],
    time: str | None,
    rate: float | None,
    variable: str | None,
    matlab: bool = False,
) -> dict[str, Raw]:
    """Datasets by path (relative to the group `variable`, or the root). MATLAB v7.3 stores arrays transposed;
    vectors (all a channel can be) read the same either way. A dataset's `unit` or `units` attribute is its unit.

    The HDF5 library reads in a child process (`core.isolated`: a damaged file may crash it), which gives back the
    names of the datasets and those a channel needs (each checked for its size before it is read); what they
    hold is checked here."""
    src = str(path)
    what = f"HDF5{' (MATLAB v7.3)' if matlab else ''}"
    keys = {ours: theirs.strip("/") for ours, theirs in channels.items()}
    size = path.stat().st_size
    try:
        datasets, loaded = in_child(_load, src, variable, matlab, list(keys.values()), time, size, size=size)
    except Damaged as exc:
        raise InputError(f"cannot read as {what}: the file is damaged: {exc.reason}", source=src) from None

    def get(name: str) -> NDArray:
        value = loaded[name][0]
        if isinstance(value, str):  # a dataset the child could not read: why
            raise InputError(f"dataset '{name}': {value}", source=src)
        return value

    first = next(iter(keys.values()), None)
    n = np.size(loaded[first][0]) if first in loaded and not isinstance(loaded[first][0], str) else 0

    def common():
        found = [c for c in TIME_NAMES if c in datasets]
        return time_vector(time, found, get, datasets, src, rate, n)

    for ours, theirs in channels.items():
        if keys[ours] not in datasets:
            raise missing("dataset" if not matlab else "channel", theirs, datasets, src, key=ours)
    stamps = stamps_of(keys, datasets, lambda k: numeric(get(k), src, f"time vector '{k}'"), common)
    raw = {}
    for ours, theirs in channels.items():
        t, tname = stamps[ours]
        y = numeric(get(keys[ours]), src, f"channel '{theirs}'")
        raw[ours] = Raw(t, y, _unit(keys[ours], loaded[keys[ours]][1], src), time=tname)
    return raw


def _unit(name: str, value: object, src: str) -> str:
    """A dataset's `unit` attribute as text: str, or bytes in UTF-8, or one of them in a 1-element array."""
    if isinstance(value, np.ndarray) and value.size == 1:
        value = value.reshape(-1)[0]
    if isinstance(value, np.generic) and value.dtype.kind in "SU":
        value = value.item()
    if isinstance(value, bytes):
        try:
            value = value.decode("utf-8")
        except UnicodeDecodeError:
            raise InputError(
                f"dataset '{name}': its unit attribute is not UTF-8 text ({clip(value, 60)})", source=src
            ) from None
    if not isinstance(value, str):
        kind = f"{value.dtype} array of shape {value.shape}" if isinstance(value, np.ndarray) else type(value).__name__
        raise InputError(f"dataset '{name}': its unit attribute is not text (a {kind})", source=src)
    return value


DEFLATE_RATIO = 1032  # the most deflate can compress: a dataset declaring more bytes than this is not in the file


def _load(src: str, variable, matlab: bool, keys: list[str], time: str | None, size: int):
    """In the child: the datasets' names (relative to the group of the channels) and, for each name a channel may
    need (itself, its own time vector, the common time vectors), (its values or why they cannot be read, its unit
    attribute as stored)."""
    import h5py

    with h5py.File(src, "r") as f:
        group = _group(f, keys, variable, matlab, src)
        datasets: list[str] = []
        group.visititems(lambda name, obj: datasets.append(_text(name)) if isinstance(obj, h5py.Dataset) else None)
        wanted = [*keys, *(own_time_name(k) for k in keys), *([time] if time else TIME_NAMES)]
        loaded = {}
        for name in dict.fromkeys(wanted):
            if name in datasets:
                d = group[name]
                attrs = d.attrs
                unit = attrs["unit"] if "unit" in attrs else attrs["units"] if "units" in attrs else ""
                loaded[name] = (_values(d, size), unit)
        return datasets, loaded


def _values(d, size: int):
    """A dataset's values, or why they are not read: not numeric, or more bytes than the file can hold."""
    if d.dtype.kind not in "biuf":
        return f"not numeric (type {d.dtype})"
    declared = int(np.prod(d.shape, dtype=float)) * d.dtype.itemsize if d.shape is not None else 0
    if declared > DEFLATE_RATIO * size + (1 << 20):
        return (
            f"it declares shape {d.shape} of {d.dtype} ({declared / 2**30:.3g} GiB), more than the file's {size} "
            f"bytes can hold even compressed: the file is damaged"
        )
    return d[()]


def _group(f, names: Sequence[str], variable: str | None, matlab: bool, src: str):
    """The group holding the channels: `variable`, else (MATLAB v7.3) the one struct at the top level when no
    channel is there, else the root."""
    import h5py

    group = f
    if variable is not None:
        if variable not in f or not isinstance(f[variable], h5py.Group):
            tops = [k for k in f if not k.startswith("#")]  # '#refs#': MATLAB's internal references
            if variable in f:
                raise InputError(f"variable '{variable}' is not a struct (HDF5 group) of channels", source=src)
            raise missing("variable", variable, tops, src)
        group = f[variable]
    elif matlab:
        tops = [k for k in f if not k.startswith("#")]
        structs = [k for k in tops if isinstance(f[k], h5py.Group)]
        if not any(name in f for name in names) and len(structs) == 1:
            group = f[structs[0]]
    return group
