"""Tables any system's campaigns can have (the `System.tables` and `System.render` defaults): per parameter the
truth, the mean estimate, its spread over runs (or, for one fit, its 95 % interval from the bound) and the bound."""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from rich.table import Table

from ..core.errors import InputError
from ..identify.records import Campaign

Z95 = 1.959963984540054
COLUMNS = ("file", "parameter", "truth", "mean", "sd", "ci95_half_width", "crlb_sd", "re_percent")


def _g(value) -> str:
    return "–" if value is None or not np.isfinite(value) else f"{value:.6g}"


def parameter_rows(c: Campaign, file: str) -> list[list]:
    """One row per parameter: COLUMNS' values (NaN where a figure does not exist)."""
    s, b = c.summary, c.bound
    rows = []
    for j, name in enumerate(c.names):
        crlb_sd = float(b.sd[j]) if np.isfinite(b.sd[j]) else float("nan")
        half = Z95 * crlb_sd if len(c.records) == 1 else float("nan")
        rows.append([
            file, name, float("nan") if c.truth is None else float(c.truth[j]), float(s.mean[j]), float(s.sd[j]),
            half, crlb_sd, float("nan") if s.re_percent is None else float(s.re_percent[j]),
        ])  # fmt: skip
    return rows


def parameter_tables(campaigns: Sequence[Campaign], files: Sequence[str]) -> list[Table]:
    """A rich table per campaign."""
    out = []
    for c, f in zip(campaigns, files, strict=True):
        t = Table(title=f"{Path(f).stem} · {c.system} · {c.objective} · {len(c.records)} run(s)", title_justify="left")
        for col in ("parameter", "truth", "mean", "sd over runs", "95 % ± (one fit)", "CRLB sd", "RE %"):
            t.add_column(col, justify="left" if col == "parameter" else "right")
        for row in parameter_rows(c, f):
            t.add_row(row[1], *(_g(v) for v in row[2:]))
        out.append(t)
    return out


def render_parameters(campaigns: Sequence[Campaign], files: Sequence[str], fmt: str) -> str:
    """The parameter rows as Markdown or CSV."""
    rows = [r for c, f in zip(campaigns, files, strict=True) for r in parameter_rows(c, f)]
    if fmt == "csv":
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow(COLUMNS)
        writer.writerows(rows)
        return buf.getvalue()
    if fmt == "md":
        lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
        lines += ["| " + " | ".join([r[0], r[1], *(_g(v) for v in r[2:])]) + " |" for r in rows]
        return "\n".join(lines) + "\n"
    raise InputError(f"--format {fmt} is not available for these campaigns; use table, md, csv or json")
