"""CSV logger exports (`.csv`/`.txt`): one time column and the channels, read and written.

Reading goes through the measurement table reader (`io.measurement.read_table`): the time column is the one named
by `time=`, else `t`, `time` (`TIME_NAMES`), else the stamps are k / rate; its stamps may be numbers or ISO 8601
date-times (a logger's export), read as seconds after the first. A column's header may carry its unit
(`ACC_FL [g]`, `POT1 (mm)`: the column is then also found as `ACC_FL`); otherwise a CSV declares no units: pass
them (`units=`). A logger's multi-rate export leaves a slower channel's cells empty between its samples: each
channel is read at the rows that hold it.

Writing: one time column `t` [s] and the channels, numbers to 17 significant digits (they read back exactly);
`#` lines before the header hold the comment, the start and the units for people, but `read_record` reads no units
from a CSV: pass them (`units=`). One rate only: channels with different time stamps are an InputError.
"""

from __future__ import annotations

import datetime as dt
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ...core.errors import InputError
from ...core.files import atomic_path
from ..measurement import read_table
from .base import TIME_NAMES, LoggerFormat, Raw, groups, missing, register, time_vector

CSV_FORBIDDEN = (",", ";", "\t", "\n", "\r")  # read_table's separators and line ends
HEADER_UNIT = re.compile(r"^(?P<name>.*?\S)\s*[\[(](?P<unit>[^\[\]()]+)[\])]$")  # ACC_FL [g], POT1 (mm)


@dataclass(frozen=True)
class Table:
    """A CSV's columns by name, a column's unit when its header declares one (`name [unit]` or `name (unit)`: the
    column is then also found by its bare name), and the rows each column leaves empty."""

    columns: dict[str, NDArray]
    source: str
    units: dict[str, str] = field(default_factory=dict)
    blank: dict[str, NDArray] = field(default_factory=dict)  # name -> (n,) bool: the rows without its sample


def _with_header_units(table) -> Table:
    """The table's columns, each also under its bare name when its header carries a unit (which is kept)."""
    columns, blank = table.columns, dict(table.blank)
    out, units = dict(columns), {}
    for header, values in columns.items():
        m = HEADER_UNIT.match(header)
        if m and m["name"] not in columns:
            out[m["name"]] = values
            units[m["name"]] = units[header] = m["unit"].strip()
            if header in blank:
                blank[m["name"]] = blank[header]
    return Table(out, table.source, units, blank)


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
        table = _with_header_units(read_table(path, timestamps=candidates, blanks=True))
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
        if not np.all(np.isfinite(t)):
            raise InputError(f"the time column '{tname}' has empty cells: every row needs its time", source=src)
        raw = {}
        for ours, theirs in channels.items():
            if theirs not in table.columns:
                raise missing("column", theirs, list(table.columns), src, key=ours)
            values, unit = table.columns[theirs], table.units.get(theirs, "")
            own = ~table.blank.get(theirs, np.zeros(values.size, dtype=bool))  # a slower channel's rows (multi-rate)
            if not own.any():
                raise InputError(f"column '{theirs}' ('{ours}') is empty", source=src)
            raw[ours] = Raw(t, values, unit, time=tname) if own.all() else Raw(t[own], values[own], unit, time=tname)
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
