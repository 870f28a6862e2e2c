"""Summary tables of the car's campaigns: rich (terminal), Markdown, CSV, LaTeX (booktabs); JSON is report's."""

from __future__ import annotations

import csv
import io

import numpy as np
from rich.table import Table

from ...identify.records import Campaign


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
    """Per parameter: truth, mean estimate, RE of the mean, spread over runs, the bound; then the NRE figures.
    One fit (measured data): the estimate with its 95 % interval from the bound at the estimate, no spread."""
    if len(c.records) == 1:
        return single_fit_table(c)
    s, b = c.summary, c.bound
    table = Table(title=campaign_title(c), title_justify="left")
    for col in ("parameter", "truth", "mean", "RE of mean %", "sd over runs %", "CRLB sd %", "sd/CRLB"):
        table.add_column(col, justify="left" if col == "parameter" else "right")
    at_bound = c.at_bound
    for j, name in enumerate(c.names):
        finite = np.isfinite(b.re_sd_percent[j]) and b.re_sd_percent[j] > 0
        ratio = s.re_sd_percent[j] / b.re_sd_percent[j] if finite else None
        flag = "" if b.identifiable[j] else " (not identifiable)"
        flag += f" (at a bound in {at_bound[name]} runs)" if name in at_bound else ""
        table.add_row(
            name + flag,
            _g(None if c.truth is None else c.truth[j]),
            _g(s.mean[j]),
            _f(None if s.re_percent is None else s.re_percent[j]),
            _f(s.re_sd_percent[j]),
            _f(b.re_sd_percent[j]),
            _f(ratio, 2),
        )
    table.caption = (
        f"NRE of mean {_f(s.nre_percent)} % · per-run NRE median {_f(s.per_run_nre_median)} % · "
        f"RMS {_f(s.per_run_nre_rms)} % · CRLB NRE {_f(b.nre_rms_percent)} % · NRE/CRLB {_f(s.nre_over_crlb, 2)} · "
        f"χ²/sample {_f(s.chi2_median, 2)} · "
        f"evaluations/run {s.evaluations.mean():.0f} · converged {_count(s.converged, len(c.records))} · "
        f"penalised {s.penalised} · wall {s.wall_s:.1f} s"
    )
    table.caption_justify = "left"
    return table


def single_fit_table(c: Campaign) -> Table:
    """One fit: per parameter the estimate, its 95 % interval (1.96 x the bound's sd at the estimate, for the noise
    the data imply), the bound relative to the estimate, and RE when the truth is declared."""
    s, b, r = c.summary, c.bound, c.records[0]
    table = Table(title=campaign_title(c), title_justify="left")
    for col in ("parameter", "truth", "estimate", "± 95 % (bound)", "CRLB sd %", "RE %"):
        table.add_column(col, justify="left" if col == "parameter" else "right")
    at_bound = c.at_bound
    for j, name in enumerate(c.names):
        flag = "" if b.identifiable[j] else " (not identifiable)"
        interval = _g(1.96 * b.sd[j])
        if name in at_bound:  # the optimum lies beyond the box: no interval means anything
            flag, interval = flag + " AT BOUND", f"on bound [{c.lower[j]:.4g}, {c.upper[j]:.4g}]"
        table.add_row(
            name + flag, _g(None if c.truth is None else c.truth[j]), _g(r.estimate[j]), interval,
            _f(b.re_sd_percent[j]), _f(None if s.re_percent is None else s.re_percent[j]),
        )  # fmt: skip
    table.caption = (
        f"one fit (every run would fit the same data) · χ²/sample {_f(s.chi2_median, 2)} · evaluations "
        f"{r.evaluations} · penalised {s.penalised} · wall {s.wall_s:.1f} s"
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


def _grid(group: list[Campaign], published: dict | None = None) -> tuple[list[str], list[list[str]]]:
    """The paper's layout: a row per parameter (then NRE rows), Est and RE columns per algorithm,
    and the published RE beside ours where `published` has it."""
    first = group[0]
    header = ["", "true"]
    refs = [published_for(published, c) for c in group]
    for c, ref in zip(group, refs, strict=True):
        name = c.config.identify.algorithm.name
        header += [f"{name} est", f"{name} RE %"] + ([f"{name} paper RE %"] if ref else [])
    rows = []
    for j, pname in enumerate(first.names):
        row = [pname, _g(None if first.truth is None else first.truth[j])]
        for c, ref in zip(group, refs, strict=True):
            s = c.summary
            row += [_g(s.mean[j]), _f(None if s.re_percent is None else s.re_percent[j])]
            if ref:
                row.append(_f(ref["re"].get(pname)))
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
        row = [label, ""]
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
        parts.append("| " + " | ".join(header) + " |")
        parts.append("|" + "|".join(["---"] + ["---:"] * (len(header) - 1)) + "|")
        parts.extend("| " + " | ".join(r) + " |" for r in rows)
        parts.append("")
    return "\n".join(parts)


def latex(campaigns: list[Campaign], published: dict | None = None) -> str:
    """The same tables for LaTeX with booktabs."""
    parts = []
    for group in grouped(campaigns):
        header, rows = _grid(group, published)
        esc = [h.replace("%", r"\%").replace("_", r"\_") for h in header]
        parts.append(r"\begin{table}[ht]\centering")
        parts.append(
            r"\caption{" + group_title(group[0]).replace("%", r"\%").replace("`", "").replace("_", r"\_") + "}"
        )
        parts.append(r"\begin{tabular}{l" + "r" * (len(header) - 1) + "}")
        parts.append(r"\toprule")
        parts.append(" & ".join(esc) + r" \\")
        parts.append(r"\midrule")
        for i, r in enumerate(rows):
            if i == len(group[0].names):
                parts.append(r"\midrule")
            parts.append(" & ".join(cell.replace("%", r"\%").replace("–", "--") for cell in r) + r" \\")
        parts.append(r"\bottomrule")
        parts.append(r"\end{tabular}")
        parts.append(r"\end{table}")
        parts.append("")
    return "\n".join(parts)


CSV_COLUMNS = (
    "file", "algorithm", "objective", "sensors", "noise_level", "runs", "parameter", "truth", "mean",
    "re_percent", "sd_percent", "crlb_sd_percent", "nre_percent", "per_run_nre_median", "per_run_nre_rms",
    "crlb_nre_rms_percent", "nre_over_crlb", "evaluations_per_run", "wall_s",
)  # fmt: skip


def csv_rows(campaigns: list[Campaign], files: list[str]) -> list[list]:
    """Long format: one row per campaign and parameter, campaign figures repeated on each row."""
    rows = []
    for c, file in zip(campaigns, files, strict=True):
        s, b, cfg = c.summary, c.bound, c.config
        for j, name in enumerate(c.names):
            rows.append([
                file, cfg.identify.algorithm.name, cfg.identify.objective, cfg.sensors, cfg.noise.level,
                len(c.records), name, None if c.truth is None else c.truth[j], s.mean[j],
                None if s.re_percent is None else s.re_percent[j], s.re_sd_percent[j], b.re_sd_percent[j],
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
