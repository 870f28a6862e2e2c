"""Summary tables of campaigns: rich (terminal), Markdown, CSV, LaTeX (booktabs), JSON."""

from __future__ import annotations

from rich.table import Table

from ..campaign import Campaign


def _f(value, digits: int = 3) -> str:
    if value is None:
        return "–"
    return f"{value:.{digits}f}"


def _g(value) -> str:
    return "–" if value is None else f"{value:.6g}"


def campaign_title(c: Campaign) -> str:
    cfg = c.config
    src = f"data {c.data_file}" if c.data_file else f"Np = {100 * cfg.noise.level:g} %"
    return (
        f"{cfg.identify.algorithm.name} · objective {cfg.identify.objective} · sensors {cfg.sensors} · {src} · "
        f"{len(c.records)} runs"
    )


def summary_table(c: Campaign) -> Table:
    """Per parameter: truth, mean estimate, RE of the mean, spread over runs, the bound; then the NRE figures."""
    s, b = c.summary, c.bound
    table = Table(title=campaign_title(c), title_justify="left")
    for col in ("parameter", "truth", "mean", "RE of mean %", "sd over runs %", "CRLB sd %", "sd/CRLB"):
        table.add_column(col, justify="left" if col == "parameter" else "right")
    for j, name in enumerate(c.names):
        ratio = s.re_sd_percent[j] / b.re_sd_percent[j] if b.re_sd_percent[j] > 0 else None
        flag = "" if b.identifiable[j] else " (not identifiable)"
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
        f"evaluations/run {s.evaluations.mean():.0f} · penalised {s.penalised} · wall {s.wall_s:.1f} s"
    )
    table.caption_justify = "left"
    return table
