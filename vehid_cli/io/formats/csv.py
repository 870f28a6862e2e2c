"""CSV logger exports (`.csv`/`.txt`): one time column and the channels, read and written.

Reading goes through the measurement table reader (`io.measurement.read_table`): the time column is the one named
by `time=`, else `t`, `time` (`TIME_NAMES`), else the stamps are k / rate; its stamps may be numbers or ISO 8601
date-times (a logger's export), read as seconds after the first. A CSV declares no units: pass them (`units=`).

Writing: one time column `t` [s] and the channels, numbers to 17 significant digits (they read back exactly);
`#` lines before the header hold the comment, the start and the units for people, but `read_record` reads no units
from a CSV: pass them (`units=`). One rate only: channels with different time stamps are an InputError.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ...core.errors import InputError
from ...core.files import atomic_path
from ..measurement import read_table
from .base import TIME_NAMES, LoggerFormat, Raw, groups, missing, register, time_vector

CSV_FORBIDDEN = (",", ";", "\t", "\n", "\r")  # read_table's separators and line ends


@register
class Csv(LoggerFormat):
    """CSV with numeric or ISO 8601 time stamps (module docstring)."""

    name = "csv"
    suffixes = (".csv", ".txt")
    writes = (".csv", ".txt")
    rank = 10
    reports_missing_file = True  # read_table names a missing file itself

    def read(
        self, path: Path, channels: Mapping[str, str], *, time: str | None, rate: float | None, variable: str | None
    ) -> dict[str, Raw]:
        candidates = (time,) if time else TIME_NAMES
        table = read_table(path, timestamps=candidates)
        src = table.source
        t, tname = time_vector(
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
                raise missing("column", theirs, list(table.columns), src, key=ours)
            raw[ours] = Raw(t, table.columns[theirs], time=tname)
        return raw

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
            _write_csv(tmp, runs, names, units, start, comment, str(path))


def _write_csv(tmp: Path, runs, theirs, units, start, comment, src) -> None:
    found = groups(runs)
    if len(found) > 1:
        listed = "; ".join(
            ", ".join(f"'{o}' ('{theirs[o]}')" for o in members) + f": {t.size} stamps from {t[0]:.9g} s"
            for t, members in found
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
    t = found[0][0]
    head = [f"# {line}" for line in comment.splitlines()]
    if start is not None:
        head.append(f"# start: {start.isoformat()}")
    head.append("# units: " + ", ".join(f"{theirs[o]} [{units[o] or 'SI'}]" for o in runs) + " (t [s])")
    table = np.column_stack([t] + [runs[o][1] for o in runs])
    with open(tmp, "w", encoding="utf-8", newline="\n") as fh:
        fh.write("\n".join(head) + "\n" + ",".join(["t", *theirs.values()]) + "\n")
        np.savetxt(fh, table, fmt="%.17g", delimiter=",")
