"""What every system's tables are built from, and the tables any system gets by default (`System.tables`,
`System.render`): per unknown its unit, the truth, the estimate (the mean over runs, or one fit's) with its 95 %
interval (the spread over runs, or one fit's from the bound at the estimate), the bound, an estimate at a bound
marked. `parameter_rows` gives the numbers at full precision and as text rounded to their uncertainty
(core.digits), for any format (the terminal, Markdown, LaTeX, CSV, HTML)."""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rich.table import Table

from ..core.digits import DASH, interval, rounded, significant
from ..core.errors import InputError
from ..identify.records import Campaign

COLUMNS = (
    "file", "parameter", "unit", "truth", "mean", "sd", "ci95_low", "ci95_high", "ci95_from", "ci95_half_width",
    "crlb_sd", "re_percent", "at_bound_runs",
)  # fmt: skip
TEXT_COLUMNS = ("parameter", "unit", "truth", "estimate ± 95 %", "95 % interval", "CRLB sd %", "RE %")


@dataclass(frozen=True)
class ParameterRow:
    """One unknown of a campaign as every table shows it. Numbers at full precision in the parameter's unit (NaN
    where a figure does not exist); the `*_text` properties round them to their uncertainty for people."""

    name: str
    unit: str
    truth: float
    configured: float
    estimate: float  # the mean over runs, or the one fit's estimate
    half95: float  # half-width of the 95 % interval (NaN: none, e.g. one fit on a bound)
    sd: float  # spread over runs (0 for one fit)
    sd_percent: float  # the spread relative to the truth (or the mean) [%]
    crlb_sd: float  # the Cramér–Rao bound's sd
    crlb_sd_percent: float
    re_percent: float  # RE of the estimate [%] (NaN: truth unknown)
    at_bound: int  # runs whose estimate sits on a bound of the search box
    runs: int
    identifiable: bool
    lower: float  # the search box
    upper: float

    @property
    def low(self) -> float:
        return self.estimate - self.half95

    @property
    def high(self) -> float:
        return self.estimate + self.half95

    @property
    def interval_from(self) -> str:
        """Where the 95 % interval comes from: 'runs' (the spread over a campaign's runs) or 'bound' (one fit)."""
        return "bound" if self.runs == 1 else "runs"

    @property
    def flag(self) -> str:
        """'AT BOUND' (one fit on a bound of its box: no interval means anything), 'AT BOUND in k/N runs', or ''."""
        if not self.at_bound:
            return ""
        return "AT BOUND" if self.runs == 1 else f"AT BOUND in {self.at_bound}/{self.runs} runs"

    @property
    def label(self) -> str:
        """The name with what a reader must know: not identifiable, at a bound."""
        extra = [] if self.identifiable else ["(not identifiable)"]
        return " ".join([self.name, *extra, *([self.flag] if self.flag else [])])

    @property
    def estimate_text(self) -> str:
        """The estimate rounded to its interval (6 significant digits without one)."""
        return rounded(self.estimate, self.half95)[0]

    @property
    def half_text(self) -> str:
        return rounded(self.estimate, self.half95)[1]

    @property
    def with_interval(self) -> str:
        """'1235 ± 12'; one fit on a bound: '4550 AT BOUND' (no interval: the optimum lies beyond the box)."""
        if self.runs == 1 and self.at_bound:
            return f"{significant(self.estimate)} AT BOUND"
        v, u = rounded(self.estimate, self.half95)
        return v if u == DASH else f"{v} ± {u}"

    @property
    def interval_text(self) -> str:
        """'[1223, 1247]'; one fit on a bound: the search box, 'box [lo, hi]'."""
        if self.runs == 1 and self.at_bound:
            return f"box [{significant(self.lower, 4)}, {significant(self.upper, 4)}]"
        return interval(self.low, self.high) if np.isfinite(self.half95) else DASH

    @property
    def truth_text(self) -> str:
        return significant(self.truth)


def _nan(value) -> float:
    return float("nan") if value is None else float(value)


def parameter_rows(c: Campaign) -> list[ParameterRow]:
    """One row per unknown of the campaign, its unit from where the parameter is declared (Campaign.units)."""
    s, b = c.summary, c.bound
    centre, half = c.interval95()
    units, at_bound = c.units, c.at_bound
    re_sd = s.re_sd_percent
    return [
        ParameterRow(
            name=name,
            unit=units[name],
            truth=_nan(None if c.truth is None else c.truth[j]),
            configured=float(c.nominal[j]),
            estimate=float(centre[j]),
            half95=float(half[j]),
            sd=float(s.sd[j]),
            sd_percent=float(re_sd[j]),
            crlb_sd=float(b.sd[j]),
            crlb_sd_percent=float(b.re_sd_percent[j]),
            re_percent=_nan(None if s.re_percent is None else s.re_percent[j]),
            at_bound=at_bound.get(name, 0),
            runs=len(c.records),
            identifiable=bool(b.identifiable[j]),
            lower=float(c.lower[j]),
            upper=float(c.upper[j]),
        )  # fmt: skip
        for j, name in enumerate(c.names)
    ]


def fixed(value, digits: int = 3) -> str:
    """A percentage or ratio with a fixed number of decimals ('–' where it does not exist)."""
    return DASH if value is None or not np.isfinite(value) else f"{value:.{digits}f}"


def text_cells(row: ParameterRow) -> list[str]:
    """TEXT_COLUMNS of one row (rounded for people)."""
    return [
        row.label, row.unit, row.truth_text, row.with_interval, row.interval_text, fixed(row.crlb_sd_percent),
        fixed(row.re_percent),
    ]  # fmt: skip


def csv_cells(file: str, row: ParameterRow) -> list:
    """COLUMNS of one row (full precision, for machines)."""
    return [
        file, row.name, row.unit, row.truth, row.estimate, row.sd, row.low, row.high, row.interval_from, row.half95,
        row.crlb_sd, row.re_percent, row.at_bound,
    ]  # fmt: skip


def parameter_tables(campaigns: Sequence[Campaign], files: Sequence[str]) -> list[Table]:
    """A rich table per campaign."""
    out = []
    for c, f in zip(campaigns, files, strict=True):
        t = Table(title=f"{Path(f).stem} · {c.system} · {c.objective} · {len(c.records)} run(s)", title_justify="left")
        shown = [i for i, col in enumerate(TEXT_COLUMNS) if col != "95 % interval"]  # 80 columns: ± says it
        for i in shown:
            add_column(t, TEXT_COLUMNS[i])
        for row in parameter_rows(c):
            cells = text_cells(row)
            t.add_row(*(cells[i] for i in shown))
        t.caption = interval_note(c)
        t.caption_justify = "left"
        out.append(t)
    return out


def add_column(table: Table, header: str) -> None:
    """A column of a parameter table: names and units left-aligned, numbers right; a name, a unit and an estimate
    with its interval never wrap (the headers and the other columns give way in a narrow terminal)."""
    keep = header in ("parameter", "unit") or "±" in header
    widest = max(len(word) for word in header.split())  # a narrow terminal wraps a header, never hides it
    justify = "left" if header in ("parameter", "unit") else "right"
    table.add_column(header, justify=justify, no_wrap=keep, min_width=widest)


def interval_note(c: Campaign) -> str:
    """What the ± of a campaign's table is."""
    if c.single_fit:
        return "± 95 %: one fit, 1.96 x the Cramér–Rao sd at the estimate (widened by sqrt(χ²) above the noise)"
    return f"± 95 %: 1.96 x the sd over {len(c.records)} runs (where one run's estimate falls)"


# ------------------------------------------------------------------------------------------ text formats


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[str]], left: int = 1) -> list[str]:
    """Markdown table lines, the first `left` columns left-aligned, the others right-aligned."""
    align = ["---" if i < left else "---:" for i in range(len(header))]

    def line(cells: Sequence[str]) -> str:
        return "| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |"

    return [line(header), "|" + "|".join(align) + "|", *(line(r) for r in rows)]


def latex_text(text: str) -> str:
    """Plain text (a name, a caption, a cell) for LaTeX: its special characters escaped, ± and the units' powers
    in math mode, the dash as an en-dash."""
    out = text.replace("\\", r"\textbackslash{}")
    for a, b in (("%", r"\%"), ("_", r"\_"), ("&", r"\&"), ("#", r"\#"), ("`", "")):
        out = out.replace(a, b)
    for a, b in (("±", r"$\pm$"), ("^2", r"$^2$"), ("^3", r"$^3$"), ("²", r"$^2$"), ("³", r"$^3$"), ("χ", r"$\chi$")):
        out = out.replace(a, b)
    return out.replace("–", "--")


def latex_table(header: Sequence[str], rows: Sequence[Sequence[str]], caption: str, rule_after: int = 0) -> list[str]:
    """A booktabs table (first column left, the others right); a \\midrule after `rule_after` body rows."""
    lines = [r"\begin{table}[ht]\centering", r"\caption{" + latex_text(caption) + "}"]
    lines += [r"\begin{tabular}{l" + "r" * (len(header) - 1) + "}", r"\toprule"]
    lines += [" & ".join(latex_text(h) for h in header) + r" \\", r"\midrule"]
    for i, r in enumerate(rows):
        if rule_after and i == rule_after:
            lines.append(r"\midrule")
        lines.append(" & ".join(latex_text(c) for c in r) + r" \\")
    return lines + [r"\bottomrule", r"\end{tabular}", r"\end{table}", ""]


def render_parameters(campaigns: Sequence[Campaign], files: Sequence[str], fmt: str) -> str:
    """The parameter rows as Markdown, LaTeX (rounded, with units and the 95 % interval) or CSV (full precision)."""
    if fmt == "csv":
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow(COLUMNS)
        writer.writerows(csv_cells(f, r) for c, f in zip(campaigns, files, strict=True) for r in parameter_rows(c))
        return buf.getvalue()
    if fmt not in ("md", "latex"):
        raise InputError(f"--format {fmt} is not available for these campaigns; use table, md, latex, csv or json")
    parts: list[str] = []
    for c, f in zip(campaigns, files, strict=True):
        title = f"{Path(f).stem} · {c.system} · {c.objective} · {len(c.records)} run(s); {interval_note(c)}"
        body = [text_cells(r) for r in parameter_rows(c)]
        if fmt == "latex":
            parts += latex_table(TEXT_COLUMNS, body, title)
        else:
            parts += [f"**{title}**", "", *markdown_table(TEXT_COLUMNS, body, left=2), ""]
    return "\n".join(parts)
