"""Vehicle measurement files (SPEC section 2): read and validate, write atomically.

Format: CSV with a header row, `#` comment lines allowed, uniform time step. Columns `t` [s],
`road1..road4` [m], and `acc1..acc4` [m/s²] and/or `disp1..disp4` [m]; extra columns are ignored.
"""

from __future__ import annotations

import io
import math
from collections.abc import Collection, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..core.errors import InputError
from ..core.files import atomic_path, read_text

ROAD_COLUMNS = tuple(f"road{i}" for i in range(1, 5))
ACC_COLUMNS = tuple(f"acc{i}" for i in range(1, 5))
DISP_COLUMNS = tuple(f"disp{i}" for i in range(1, 5))
UNIFORM_TOLERANCE = 1e-3  # time steps may deviate from the median step by this fraction (print round-off)


@dataclass(frozen=True)
class Measurement:
    """One vehicle run: time grid, road under each tyre, and the measured body-point responses."""

    t: NDArray  # (n,) [s], uniform
    road: NDArray  # (n, 4) [m]
    acc: NDArray | None  # (n, 4) [m/s²]
    disp: NDArray | None  # (n, 4) [m]
    source: str

    @property
    def dt(self) -> float:
        """Time step [s]."""
        return float((self.t[-1] - self.t[0]) / (self.t.size - 1))


@dataclass(frozen=True)
class Table:
    """A numeric CSV table: column name -> values, with where it came from."""

    columns: dict[str, NDArray]
    source: str
    blank: dict[str, NDArray] = field(default_factory=dict)  # name -> (n,) bool: empty cells (read_table's blanks)

    def column(self, name: str) -> NDArray:
        if name not in self.columns:
            raise InputError(
                f"column '{name}' is missing (columns present: {', '.join(self.columns)})", source=self.source
            )
        return self.columns[name]


DELIMITERS = {";": "';'", "\t": "tab", ",": "','"}
DECIMAL_COMMA_HINT = "decimal comma? use '.' as the decimal separator, or ';'-separated columns"


def _delimiter(header: str) -> str:
    """The field separator, from the header line: ';' (European spreadsheet exports), else tab, else ','."""
    return next((d for d in DELIMITERS if d in header), ",")


def _number(cell: str, decimal_comma: bool) -> float:
    """A cell as a float; with `decimal_comma`, '1,25' reads as 1.25 (raises ValueError if not a number)."""
    try:
        return float(cell)
    except ValueError:
        if decimal_comma and cell.count(",") == 1 and "." not in cell:
            return float(cell.replace(",", "."))
        raise


def _timestamp(cell: str, decimal_comma: bool) -> datetime | None:
    """An ISO 8601 date-time ('2025-11-14 20:07:10.531160', 'T' or ' ' between, 'Z' or an offset allowed), or None."""
    text = cell.strip()
    text = text[:-1] + "+00:00" if text.endswith("Z") else text
    for candidate in (text, text.replace(",", ".")) if decimal_comma else (text,):
        try:
            return datetime.fromisoformat(candidate)
        except ValueError:
            continue
    return None


def read_table(path: str | Path, *, timestamps: Collection[str] = (), blanks: bool = False) -> Table:
    """Read a numeric CSV with a header row and `#` comments. Raises InputError naming file, row and column.

    Columns are separated by ',', ';' or tabs (from the header line); with ';' or tabs, decimal commas read.
    A column named in `timestamps` may hold ISO 8601 date-times (logger exports): it reads as seconds after the
    first row's. With `blanks`, an empty cell is NaN (a channel sampled more slowly than the file's rows: a logger's
    multi-rate export); without, it is an error."""
    source = str(path)
    text = read_text(path, "file", "a CSV file", encoding="utf-8-sig")  # tolerate a BOM (spreadsheet exports)
    lines = [
        (no, line)
        for no, line in enumerate(text.splitlines(), start=1)
        if line.strip() and not line.lstrip().startswith("#")
    ]
    if not lines:
        raise InputError("empty file: expected a header row and data rows", source=source)
    header_no, header = lines[0]
    sep = _delimiter(header)
    decimal_comma = sep != ","
    names = [h.strip() for h in header.split(sep)]
    if any(not n for n in names):
        raise InputError(f"header (line {header_no}) has an empty column name", source=source)
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise InputError(f"header (line {header_no}) repeats column(s) {', '.join(dupes)}", source=source)
    rows = lines[1:]
    if not rows:
        raise InputError("no data rows after the header", source=source)
    values = np.empty((len(rows), len(names)))
    empty = np.zeros(values.shape, dtype=bool)
    stamps: dict[int, list[datetime]] = {c: [] for c, n in enumerate(names) if n in set(timestamps)}
    for r, (no, line) in enumerate(rows):
        cells = line.split(sep)
        if len(cells) != len(names):
            hint = f"; {DECIMAL_COMMA_HINT}" if sep == "," and len(cells) > len(names) else ""
            raise InputError(
                f"line {no} has {len(cells)} fields, the header has {len(names)} ({', '.join(names)}; separated by "
                f"{DELIMITERS[sep]}){hint}",
                source=source,
            )
        for c, cell in enumerate(cells):
            if blanks and not cell.strip() and c not in stamps:
                values[r, c] = np.nan
                empty[r, c] = True
                continue
            try:
                values[r, c] = _number(cell, decimal_comma)
            except ValueError:
                when = _timestamp(cell, decimal_comma) if c in stamps and len(stamps[c]) == r else None
                if when is not None:
                    stamps[c].append(when)
                    continue
                hint = f"; {DECIMAL_COMMA_HINT}" if "," in cell or cell.count(".") > 1 else ""
                raise InputError(
                    f"column '{names[c]}', line {no}: expected a number, got '{cell.strip()}'{hint}", source=source
                ) from None
    for c, when in stamps.items():
        if not when:
            continue
        if len(when) != len(rows):  # a number after date-times (a date-time after a number failed above)
            raise InputError(
                f"column '{names[c]}', line {rows[len(when)][0]}: expected a date-time like the rows before it, "
                f"got '{rows[len(when)][1].split(sep)[c].strip()}'",
                source=source,
            )
        try:
            values[:, c] = [(w - when[0]).total_seconds() for w in when]
        except TypeError:
            raise InputError(
                f"column '{names[c]}' mixes date-times with and without a time zone", source=source
            ) from None
    blank = {n: empty[:, i] for i, n in enumerate(names) if empty[:, i].any()}
    return Table(columns={n: values[:, i] for i, n in enumerate(names)}, source=source, blank=blank)


def check_time(t: NDArray, source: str, column: str = "t") -> float:
    """Check a time column is finite, increasing and uniform; return its step [s]."""
    if t.size < 3:
        raise InputError(f"column '{column}' has {t.size} samples; at least 3 are needed", source=source)
    if not np.all(np.isfinite(t)):
        bad = int(np.flatnonzero(~np.isfinite(t))[0])
        raise InputError(f"column '{column}' has a non-finite value at data row {bad + 1}", source=source)
    steps = np.diff(t)
    if np.any(steps <= 0):
        bad = int(np.flatnonzero(steps <= 0)[0])
        raise InputError(
            f"column '{column}' must increase strictly; data row {bad + 2} has t = {t[bad + 1]:g} after t = {t[bad]:g}",
            source=source,
        )
    dt = float(np.median(steps))
    worst = int(np.argmax(np.abs(steps - dt)))
    # Printed time stamps carry round-off: 7 significant digits at t = 28 s put 1e-5 s of jitter on a
    # 1/1024 s step. Allow that much, and 0.1 % of the step, but not a real change of sampling rate.
    tolerance = max(UNIFORM_TOLERANCE * dt, 1e-6 * float(np.max(np.abs(t))))
    if abs(steps[worst] - dt) > tolerance:
        raise InputError(
            f"column '{column}' is not uniformly sampled: step {steps[worst]:g} s at data row {worst + 2} "
            f"against the usual {dt:g} s; resample to a uniform grid",
            source=source,
        )
    return dt


def check_finite(values: NDArray, column: str, source: str) -> None:
    """Reject NaN and infinite values, naming the column and the first bad data row."""
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        raise InputError(
            f"column '{column}' has {bad.size} non-finite value(s) (NaN or Inf), first at data row {bad[0] + 1}",
            source=source,
        )


def read_measurement(path: str | Path, *, need_responses: bool = True) -> Measurement:
    """Read a vehicle measurement file; road columns always, responses when `need_responses`."""
    table = read_table(path)
    source = table.source
    t = table.column("t")
    check_time(t, source)
    present = table.columns
    missing_road = [c for c in ROAD_COLUMNS if c not in present]
    if missing_road:
        raise InputError(
            f"road column(s) {', '.join(missing_road)} missing; expected t, road1..road4 (columns present: "
            f"{', '.join(present)})",
            source=source,
        )
    families: dict[str, NDArray | None] = {}
    for family, cols in (("acc", ACC_COLUMNS), ("disp", DISP_COLUMNS)):
        have = [c for c in cols if c in present]
        if have and len(have) < 4:
            lacking = [c for c in cols if c not in present]
            raise InputError(
                f"response column(s) {', '.join(lacking)} missing: {family} needs all four corners", source=source
            )
        families[family] = np.column_stack([present[c] for c in cols]) if have else None
    if need_responses and families["acc"] is None and families["disp"] is None:
        raise InputError("no response columns: expected acc1..acc4 and/or disp1..disp4", source=source)
    used = list(ROAD_COLUMNS) + [
        c for f, cols in (("acc", ACC_COLUMNS), ("disp", DISP_COLUMNS)) if families[f] is not None for c in cols
    ]
    for c in used:
        check_finite(present[c], c, source)
    road = np.column_stack([present[c] for c in ROAD_COLUMNS])
    return Measurement(t=t, road=road, acc=families["acc"], disp=families["disp"], source=source)


# ------------------------------------------------------------------------------------------ writing


def format_rows(table: NDArray) -> str:
    """CSV data rows, each value the shortest text that reads back to the same double (0.003, not
    0.0030000000000000001): exact, and never longer than %.17g."""
    return "".join(",".join(map(repr, row)) + "\n" for row in np.asarray(table, dtype=float).tolist())


def write_measurement_csv(
    path: str | Path,
    t: NDArray,
    road: NDArray,
    acc: NDArray | None = None,
    disp: NDArray | None = None,
    comments: Sequence[str] = (),
) -> None:
    """Write a vehicle measurement CSV atomically (shortest exact repr of every value, `#` comment header)."""
    names, cols = ["t"], [np.asarray(t)[:, None]]
    names += list(ROAD_COLUMNS)
    cols.append(road)
    for family, data in ((ACC_COLUMNS, acc), (DISP_COLUMNS, disp)):
        if data is not None:
            names += list(family)
            cols.append(data)
    write_csv(path, names, np.hstack(cols), comments)


def write_csv(path: str | Path, names: Sequence[str], table: NDArray, comments: Sequence[str] = ()) -> None:
    """Write a numeric table (n, len(names)) as CSV atomically: `#` comment lines, a header, shortest exact values."""
    buf = io.StringIO()
    for line in comments:
        for part in str(line).splitlines() or [""]:
            buf.write(f"# {part}\n")
    buf.write(",".join(names) + "\n")
    buf.write(format_rows(table))
    with atomic_path(path) as tmp:
        tmp.write_text(buf.getvalue(), encoding="utf-8")


def time_grid(duration: float, dt: float) -> NDArray:
    """Uniform grid of duration/dt samples 0, dt, ... (3 s at 1 ms: 3000 samples, as the paper's runs)."""
    n = int(math.floor(duration / dt + 1e-9))
    return np.arange(n) * dt
