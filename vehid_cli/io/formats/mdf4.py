"""ASAM MDF4 (`.mf4`/`.mdf`), the format of vehicle data loggers, read and written with asammdf.

Reading: a channel by its name, with its own time stamps (the master channel of its channel group, in seconds)
and the unit the file declares; a name in several channel groups is an InputError (the file is ambiguous).

Reading ahead (`read_ahead`, `io.read.read_ahead`): every data channel of a file whose channels would come back as at
most AHEAD_BYTES of float64 values and time stamps, read once and kept for the file's first `read` (or until
`forget`); a file of less than AHEAD_MIN_FILE bytes is left to `read` (its reader holds little beside its interpreter,
and a damaged file would be read twice), and so is a wider one (a logger's hundreds of CAN signals: reading them all
would cost more memory and time than it saves; its child then only opens it).

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
from ...core.files import FileIdentity, atomic_path, file_identity
from ...core.isolated import Damaged, in_child
from .base import LoggerFormat, Raw, groups, missing, numeric, register


@register
class Mdf4(LoggerFormat):
    """ASAM MDF4 through asammdf (module docstring)."""

    name = "mdf"
    suffixes = (".mf4", ".mdf")
    writes = (".mf4",)
    rank = 20

    def __init__(self) -> None:
        self._ahead: dict[str, tuple[FileIdentity, tuple]] = {}  # path -> (its identity, `_load`'s whole result)

    def read(
        self, path: Path, channels: Mapping[str, str], *, time: str | None, rate: float | None, variable: str | None
    ) -> dict[str, Raw]:
        src = str(path)
        key = file_identity(path)
        seen, kept = self._ahead.pop(key.path, (None, None))  # served once: not held beside its record
        if kept is not None and seen == key:
            present, located, signals = _subset(kept, list(channels.values()))
        else:
            try:  # asammdf can abort the process on damaged bytes: it reads in a child (core.isolated)
                present, located, signals = in_child(_load, src, list(channels.values()), key.size, size=key.size)
            except Damaged as exc:
                raise InputError(f"cannot read as ASAM MDF: the file is damaged: {exc.reason}", source=src) from None
        raw = {}
        for ours, theirs in channels.items():
            if theirs not in present:
                raise missing("channel", theirs, present, src, key=ours)
            if len(located[theirs]) > 1:
                listed = ", ".join(str(g) for g, _ in located[theirs])
                raise InputError(f"channel '{theirs}' is in several channel groups ({listed})", source=src, key=ours)
            samples, stamps, unit = signals[theirs]
            y = numeric(samples, src, f"channel '{theirs}'")
            t = numeric(stamps, src, f"the time stamps of channel '{theirs}'")
            raw[ours] = Raw(t, y, unit if isinstance(unit, str) else "")
        return raw

    def read_ahead(self, path: Path) -> None:
        """Every data channel of the file read now in the child and kept (module docstring); nothing kept when the
        file is small, wide, cannot be read whole, or changed while it was read."""
        try:
            key = file_identity(path)
            if key.size < AHEAD_MIN_FILE:
                return
            whole = in_child(_load, str(path), None, key.size, AHEAD_BYTES, size=key.size)
            if whole is not None and file_identity(path) == key:
                self._ahead[key.path] = (key, whole)
        except (OSError, ValueError, InputError, Damaged):  # ValueError: a path no file can have (a NUL byte)
            return

    def forget(self) -> None:
        """Drop what `read_ahead` kept and no `read` took."""
        self._ahead.clear()

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


AHEAD_BYTES = 32 * 2**20  # the most a file's channels may come back as (float64 values and stamps) to be read ahead
AHEAD_MIN_FILE = 2**20  # bytes: a smaller file is not read ahead


def _subset(whole: tuple[list[str], dict, dict], names: list[str]) -> tuple[list[str], dict, dict]:
    """`_load`'s result for `names`, from its result for every data channel (what `_load(names)` returns)."""
    present, located, signals = whole
    return present, {n: located.get(n, []) for n in names}, {n: signals[n] for n in names if n in signals}


def _load(src: str, names: list[str] | None, size: int, most: int = 0) -> tuple[list[str], dict, dict] | None:
    """In the child: the data channels' names, where each name asked for is (group, index), and for each found in
    one group its (samples, time stamps, unit) as asammdf gives them; a channel group that declares more records
    than the file can hold is refused before any is read. `names` None: every data channel, or None when they would
    come back as more than `most` bytes (every channel's values and its group's time stamps as float64)."""
    from asammdf import MDF

    mdf = MDF(src)
    try:
        masters = mdf.masters_db
        present = [
            name
            for name, where in mdf.channels_db.items()
            if any(masters.get(g) != i for g, i in where)  # the master (time) channels are not data
        ]
        if names is None:
            if sum(8 * int(g.channel_group.cycles_nr) * len(g.channels) for g in mdf.groups) > most:
                return None
            names = present
        located = {n: [(g, i) for g, i in mdf.channels_db.get(n, ()) if masters.get(g) != i] for n in names}
        signals, stamps = {}, {}
        for name in names:
            if len(located[name]) != 1:
                continue
            group, index = located[name][0]
            _check_declared(mdf, group, size, src)
            signal = mdf.get(name, group=group, index=index)
            t = np.asarray(signal.timestamps)
            if group in stamps and np.array_equal(stamps[group], t):
                t = stamps[group]  # one object: pickled once for the group's channels (a 60 s record's 16 MB -> 9)
            stamps.setdefault(group, t)
            signals[name] = (np.asarray(signal.samples), t, str(signal.unit or ""))
        return present, located, signals
    finally:
        mdf.close()


DEFLATE_RATIO = 1032  # the most deflate can compress (a DZ block): a record count beyond this is not in the file


def _check_declared(mdf, group: int, size: int, src: str) -> None:
    """InputError when channel group `group` declares more bytes of records than the file holds, even deflated."""
    cg = mdf.groups[group].channel_group
    record = int(cg.samples_byte_nr) + int(cg.invalidation_bytes_nr)
    declared = int(cg.cycles_nr) * record
    if declared > DEFLATE_RATIO * size + (1 << 20):
        raise InputError(
            f"channel group {group} declares {int(cg.cycles_nr)} samples of {record} bytes ({declared / 2**30:.3g} "
            f"GiB), more than the file's {size} bytes can hold even compressed (at most {DEFLATE_RATIO} x): the "
            f"file is damaged",
            source=src,
        )
