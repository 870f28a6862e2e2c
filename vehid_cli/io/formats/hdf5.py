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
from collections.abc import Mapping
from pathlib import Path

from numpy.typing import NDArray

from ...core.errors import InputError
from .base import TIME_NAMES, LoggerFormat, Raw, layout, missing, numeric, register, stamps_of, time_vector


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


def read_hdf5(
    path: Path,
    channels: Mapping[str, str],
    time: str | None,
    rate: float | None,
    variable: str | None,
    matlab: bool = False,
) -> dict[str, Raw]:
    """Datasets by path (relative to the group `variable`, or the root). MATLAB v7.3 stores arrays transposed;
    vectors (all a channel can be) read the same either way. A dataset's `unit` or `units` attribute is its unit."""
    import h5py

    src = str(path)
    try:
        f = h5py.File(path, "r")
    except OSError as exc:
        raise InputError(f"cannot read as HDF5{' (MATLAB v7.3)' if matlab else ''}: {exc}", source=src) from None
    with f:
        group = _group(f, channels, variable, matlab, src)
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
            return time_vector(time, found, get, datasets, src, rate, n)

        keys = {ours: theirs.strip("/") for ours, theirs in channels.items()}
        for ours, theirs in channels.items():
            if keys[ours] not in datasets:
                raise missing("dataset" if not matlab else "channel", theirs, datasets, src, key=ours)
        stamps = stamps_of(keys, datasets, lambda k: numeric(get(k), src, f"time vector '{k}'"), common)
        raw = {}
        for ours, theirs in channels.items():
            t, tname = stamps[ours]
            raw[ours] = Raw(t, numeric(get(keys[ours]), src, f"channel '{theirs}'"), unit(keys[ours]), time=tname)
        return raw


def _group(f, channels: Mapping[str, str], variable: str | None, matlab: bool, src: str):
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
        if not any(name in f for name in channels.values()) and len(structs) == 1:
            group = f[structs[0]]
    return group
