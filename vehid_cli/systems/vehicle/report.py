"""Summary tables of the car's campaigns: rich (terminal), Markdown, CSV, LaTeX (booktabs); JSON is report's."""

from __future__ import annotations

import csv
import io

import numpy as np
from rich.table import Table

from ...identify.records import Campaign
from ..report import ParameterRow, add_column, fixed, interval_note, latex_table, markdown_table, parameter_rows


def _f(value, digits: int = 3) -> str:
    if value is None:
        return "–"
    return f"{value:.{digits}f}"


def _g(value) -> str:
    return "–" if value is None else f"{value:.6g}"


def _count(k: int | None, n: int) -> str:
    return "–" if k is None else f"{k}/{n}"


def campaign_title(c: Campaign) -> str:
    cfg = c.config
    src = f"data {c.data_file}" if c.data_file else f"Np = {100 * cfg.noise.level:g} %"
    return (
        f"{cfg.identify.algorithm.name} · objective {cfg.identify.objective} · sensors {cfg.sensors} · {src} · "
        f"{len(c.records)} runs"
    )


def summary_table(c: Campaign) -> Table:
    """Per parameter: its unit, the truth, the mean estimate ± the 95 % spread over runs (rounded to it), RE of the
    mean, the spread over runs and the bound; then the NRE figures. One fit (measured data): `single_fit_table`."""
    if c.single_fit:
        return single_fit_table(c)
    s, b = c.summary, c.bound
    table = Table(title=campaign_title(c), title_justify="left")
    columns = ("parameter", "unit", "truth", "mean ± 95 %", "RE of mean %", "sd over runs %", "CRLB sd %", "sd / CRLB")
    for col in columns:
        add_column(table, col)
    for row in parameter_rows(c):
        finite = np.isfinite(row.crlb_sd_percent) and row.crlb_sd_percent > 0
        ratio = row.sd_percent / row.crlb_sd_percent if finite else None
        table.add_row(
            row.label, row.unit, row.truth_text, row.with_interval, fixed(row.re_percent), fixed(row.sd_percent),
            fixed(row.crlb_sd_percent), fixed(ratio, 2),
        )  # fmt: skip
    table.caption = (
        f"{interval_note(c)}\n"
        f"NRE of mean {_f(s.nre_percent)} % · per-run NRE median {_f(s.per_run_nre_median)} % · "
        f"RMS {_f(s.per_run_nre_rms)} % · CRLB NRE {_f(b.nre_rms_percent)} % · NRE/CRLB {_f(s.nre_over_crlb, 2)} · "
        f"χ²/sample {_f(s.chi2_median, 2)} · "
        f"evaluations/run {s.evaluations.mean():.0f} · converged {_count(s.converged, len(c.records))} · "
        f"penalised {s.penalised} · wall {s.wall_s:.1f} s"
    )
    table.caption_justify = "left"
    return table


def single_fit_table(c: Campaign) -> Table:
    """One fit: per parameter its unit, the estimate ± its 95 % interval (1.96 x the bound's sd at the estimate, for
    the noise the data imply), the bound relative to the estimate, and RE when the truth is declared; an estimate
    on a bound of its box is marked AT BOUND, with no interval (the notes name the box)."""
    s, r = c.summary, c.records[0]
    table = Table(title=campaign_title(c), title_justify="left")
    for col in ("parameter", "unit", "truth", "estimate ± 95 %", "CRLB sd %", "RE %"):
        add_column(table, col)
    for row in parameter_rows(c):
        table.add_row(
            row.label, row.unit, row.truth_text, row.with_interval, fixed(row.crlb_sd_percent), fixed(row.re_percent)
        )
    table.caption = (
        f"{interval_note(c)}\none fit (every run would fit the same data) · χ²/sample {_f(s.chi2_median, 2)} · "
        f"evaluations {r.evaluations} · penalised {s.penalised} · wall {s.wall_s:.1f} s"
    )
    table.caption_justify = "left"
    return table


# ------------------------------------------------------------------------------------------ many campaigns


def group_key(c: Campaign) -> tuple:
    """Campaigns that share everything but the algorithm go side by side in one table."""
    cfg = c.config
    return (cfg.identify.objective, cfg.sensors, cfg.noise.level, c.data_file or "", tuple(c.names))


def group_title(c: Campaign) -> str:
    cfg = c.config
    src = f"data `{c.data_file}`" if c.data_file else f"Np = {100 * cfg.noise.level:g} %"
    return f"objective {cfg.identify.objective}, sensors {cfg.sensors}, {src}"


def grouped(campaigns: list[Campaign]) -> list[list[Campaign]]:
    groups: dict[tuple, list[Campaign]] = {}
    for c in campaigns:
        groups.setdefault(group_key(c), []).append(c)
    return list(groups.values())


def published_for(published: dict | None, c: Campaign) -> dict | None:
    """The published column (est, re, nre) matching a campaign's objective, noise level and algorithm."""
    if not published:
        return None
    cfg = c.config
    for table in published.get("tables", []):
        if table.get("objective") == cfg.identify.objective and table.get("noise_level") == cfg.noise.level:
            return table.get(cfg.identify.algorithm.name)
    return None


def estimate_cell(row: ParameterRow) -> str:
    """A campaign's estimate of one parameter for the side-by-side tables: rounded to its 95 % interval, with the
    interval, and marked when it sits on a bound."""
    flag = f" ({row.flag})" if row.flag and row.runs > 1 else ""
    return row.with_interval + flag


def _grid(group: list[Campaign], published: dict | None = None) -> tuple[list[str], list[list[str]]]:
    """The paper's layout: a row per parameter with its unit (then NRE rows), the estimate ± 95 % and RE columns per
    algorithm, and the published RE beside ours where `published` has it."""
    header = ["parameter", "unit", "true"]
    refs = [published_for(published, c) for c in group]
    rows_of = [parameter_rows(c) for c in group]
    for c, ref in zip(group, refs, strict=True):
        name = c.config.identify.algorithm.name
        header += [f"{name} est ± 95 %", f"{name} RE %"] + ([f"{name} paper RE %"] if ref else [])
    rows = []
    for j, first_row in enumerate(rows_of[0]):
        row = [first_row.name, first_row.unit, first_row.truth_text]
        for ref, prow in zip(refs, (r[j] for r in rows_of), strict=True):
            row += [estimate_cell(prow), fixed(prow.re_percent)]
            if ref:
                row.append(_f(ref["re"].get(prow.name)))
        rows.append(row)
    for label, getter in (
        ("NRE of mean %", lambda s, b: s.nre_percent),
        ("per-run NRE median %", lambda s, b: s.per_run_nre_median),
        ("per-run NRE RMS %", lambda s, b: s.per_run_nre_rms),
        ("CRLB NRE %", lambda s, b: b.nre_rms_percent),
        ("NRE RMS / CRLB", lambda s, b: s.nre_over_crlb),
        ("evaluations / run", lambda s, b: float(s.evaluations.mean())),
        ("runs", lambda s, b: float(len(s.evaluations))),
        ("converged runs", lambda s, b: None if s.converged is None else float(s.converged)),
    ):
        row = [label, "", ""]
        for c, ref in zip(group, refs, strict=True):
            value = getter(c.summary, c.bound)
            digits = (
                0
                if label in ("evaluations / run", "runs", "converged runs")
                else (2 if "CRLB" in label and "/" in label else 3)
            )
            row += ["", _f(value, digits)]
            if ref:
                row.append(_f(ref.get("nre")) if label == "NRE of mean %" else "")
        rows.append(row)
    return header, rows


def markdown(campaigns: list[Campaign], published: dict | None = None) -> str:
    """One Markdown table per group of comparable campaigns, algorithms side by side."""
    parts = []
    for group in grouped(campaigns):
        header, rows = _grid(group, published)
        parts.append(f"**{group_title(group[0])}**\n")
        parts.append(f"_{interval_note(group[0])}_\n")
        parts.extend(markdown_table(header, rows, left=2))
        parts.append("")
    return "\n".join(parts)


def latex(campaigns: list[Campaign], published: dict | None = None) -> str:
    """The same tables for LaTeX with booktabs."""
    parts = []
    for group in grouped(campaigns):
        header, rows = _grid(group, published)
        caption = f"{group_title(group[0])} ({interval_note(group[0])})"
        parts += latex_table(header, rows, caption, rule_after=len(group[0].names))
    return "\n".join(parts)


CSV_COLUMNS = (
    "file", "algorithm", "objective", "sensors", "noise_level", "runs", "parameter", "unit", "truth", "mean",
    "ci95_low", "ci95_high", "ci95_from", "sd", "crlb_sd", "at_bound_runs",
    "re_percent", "sd_percent", "crlb_sd_percent", "nre_percent", "per_run_nre_median", "per_run_nre_rms",
    "crlb_nre_rms_percent", "nre_over_crlb", "evaluations_per_run", "wall_s",
)  # fmt: skip


def csv_rows(campaigns: list[Campaign], files: list[str]) -> list[list]:
    """Long format at full precision: one row per campaign and parameter (its unit, the estimate and its 95 %
    interval: over runs, or one fit's from the bound), campaign figures repeated on each row."""
    rows = []
    for c, file in zip(campaigns, files, strict=True):
        s, b, cfg = c.summary, c.bound, c.config
        for row in parameter_rows(c):
            rows.append([
                file, cfg.identify.algorithm.name, cfg.identify.objective, cfg.sensors, cfg.noise.level,
                len(c.records), row.name, row.unit, None if c.truth is None else row.truth, row.estimate,
                row.low, row.high, row.interval_from, row.sd, row.crlb_sd, row.at_bound,
                None if s.re_percent is None else row.re_percent, row.sd_percent, row.crlb_sd_percent,
                s.nre_percent, s.per_run_nre_median, s.per_run_nre_rms, b.nre_rms_percent, s.nre_over_crlb,
                float(s.evaluations.mean()), s.wall_s,
            ])  # fmt: skip
    return rows


def csv_text(campaigns: list[Campaign], files: list[str]) -> str:
    """The long CSV table (CSV_COLUMNS, csv_rows)."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    writer.writerows(csv_rows(campaigns, files))
    return buf.getvalue()


def render(campaigns: list[Campaign], files: list[str], fmt: str, published: dict | None = None) -> str:
    """The car's report as Markdown, LaTeX (booktabs) or CSV."""
    if fmt == "md":
        return markdown(campaigns, published)
    if fmt == "latex":
        return latex(campaigns, published)
    return csv_text(campaigns, files)
