"""ASAM MDF4 (`.mf4`/`.mdf`), the format of vehicle data loggers, read and written with asammdf.

Reading: a channel by its name, with its own time stamps (the master channel of its channel group, in seconds)
and the unit the file declares; a name in several channel groups is an InputError (the file is ambiguous).

Writing (`.mf4` only): ASAM MDF 4.10; channels with the same time stamps share a channel group (its master is
their time), each channel with its unit; `start` is the header's start time, `comment` the header comment.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ...core.errors import InputError
from ...core.files import atomic_path
from .base import LoggerFormat, Raw, groups, missing, numeric, register


@register
class Mdf4(LoggerFormat):
    """ASAM MDF4 through asammdf (module docstring)."""

    name = "mdf"
    suffixes = (".mf4", ".mdf")
    writes = (".mf4",)
    rank = 20

    def read(
        self, path: Path, channels: Mapping[str, str], *, time: str | None, rate: float | None, variable: str | None
    ) -> dict[str, Raw]:
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
                    raise missing("channel", theirs, present, src, key=ours)
                where = [(g, i) for g, i in mdf.channels_db[theirs] if masters.get(g) != i]
                if len(where) > 1:
                    listed = ", ".join(str(g) for g, _ in where)
                    raise InputError(
                        f"channel '{theirs}' is in several channel groups ({listed})", source=src, key=ours
                    )
                signal = mdf.get(theirs, group=where[0][0], index=where[0][1])
                y = numeric(signal.samples, src, f"channel '{theirs}'")
                raw[ours] = Raw(np.asarray(signal.timestamps, dtype=float), y, str(signal.unit or ""))
            return raw
        finally:
            mdf.close()

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
        from asammdf import MDF, Signal

        with atomic_path(path) as tmp:
            mdf = MDF(version="4.10")
            try:
                if start is not None:
                    mdf.header.start_time = start
                if comment:
                    mdf.header.comment = comment
                for t, members in groups(runs):
                    rate = (t.size - 1) / (t[-1] - t[0]) if t.size > 1 else 0.0
                    signals = [Signal(runs[o][1], t, name=names[o], unit=units[o]) for o in members]
                    mdf.append(signals, comment=f"{rate:.9g} Hz")
                with open(tmp, "wb+") as fh:  # a file object: asammdf renames a path to '.mf4'
                    mdf.save(fh, overwrite=True)
            finally:
                mdf.close()
