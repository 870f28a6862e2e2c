"""Tables of damper campaigns (campaign files with system = damper): terminal, Markdown, LaTeX, CSV and JSON.

Every number comes from the files: J (Fleps-Dezasse Eq. 7) on the training run and on each held-out run,
the estimates (with RE against the truth for synthetic data), and the real-time check.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
from rich.table import Table

from ...core.digits import significant
from ...core.jsonio import to_json
from ...identify.records import Campaign
from ..report import add_column, fixed, interval_note, latex_table, markdown_table, parameter_rows

CSV_COLUMNS = (
    "file", "model", "data_file", "runs", "parameter", "unit", "truth", "start", "mean", "ci95_low", "ci95_high",
    "ci95_from", "at_bound_runs", "re_percent", "sd",
    "J_train", "J_truth", "validation_J", "rt_dt_s", "rt_stable", "rt_factor", "rt_largest_stable_dt_s", "wall_s",
)  # fmt: skip


def _g(value, fmt: str = ".6g") -> str:
    return "–" if value is None or not np.isfinite(value) else f"{value:{fmt}}"


def label(res: Campaign, file: str) -> str:
    """How a result is named in tables and legends: the results file's stem."""
    return Path(file).stem


def source(res: Campaign) -> str:
    if res.data_file:
        return Path(res.data_file).name
    b = res.config.bench
    return f"synthetic {b.excitation}, noise {100 * res.config.noise.level:g} %"


def _J(res: Campaign) -> np.ndarray:
    """J (Eq. 7) of each run's fit."""
    return np.array([r.cost for r in res.records])


def _J_truth(res: Campaign) -> float:
    """Mean J of the truth on each run's data: the noise floor."""
    return float(np.mean([r.truth_cost for r in res.records]))


def _J_train(res: Campaign) -> str:
    J = _J(res)
    return _g(J[0], ".4g") if J.size == 1 else f"{J.mean():.4g} (± {J.std(ddof=1):.2g})"


def parameter_table(res: Campaign, file: str) -> Table:
    """Rich table of one result: per unknown its unit, truth, configured value, the estimate (mean over runs) ± its
    95 % interval (the spread over runs, or one fit's from the bound at the estimate), RE and the Cramér–Rao bound;
    an estimate on a bound of its box is marked AT BOUND."""
    algorithm = res.config.identify.algorithm.name
    title = f"{label(res, file)} · {res.findings.model} · {source(res)} · {len(res.records)} run(s) · {algorithm}"
    table = Table(title=title, title_justify="left")
    for col in ("parameter", "unit", "truth", "config", "estimate ± 95 %", "RE %", "CRLB sd %"):
        add_column(table, col)
    for row in parameter_rows(res):
        table.add_row(
            row.label, row.unit, row.truth_text, significant(row.configured), row.with_interval,
            fixed(row.re_percent), fixed(row.crlb_sd_percent),
        )  # fmt: skip
    rt = res.findings.realtime
    parts = [f"J train {_J_train(res)}"]
    if res.truth is not None:
        parts.append(f"J of the truth (noise floor) {_J_truth(res):.4g}")
        parts.append(f"NRE of mean {_g(res.summary.nre_percent, '.3f')} %")
    parts += [f"J {Path(f).stem} {j:.4g}" for f, j in res.findings.validation]
    parts.append(
        f"RK4 at {1e3 * rt.dt:g} ms {'stable' if rt.stable else 'UNSTABLE'}, "
        f"real-time factor {rt.realtime_factor:.0f}, "
        f"largest stable step {1e3 * rt.largest_stable_dt:.3g} ms"
    )
    parts.append(f"evaluations/run {np.mean(res.summary.evaluations):.0f} · wall {res.summary.wall_s:.1f} s")
    table.caption = interval_note(res) + "\n" + " · ".join(parts)
    table.caption_justify = "left"
    return table


def _md(header: list[str], rows: list[list[str]], right_from: int = 1) -> list[str]:
    return markdown_table(header, rows, left=right_from)


def estimates(res: Campaign) -> tuple[list[str], list[list[str]]]:
    """The identified parameters of one result for the text formats: (header, rows) with units, the estimate ± its
    95 % interval and the interval (rounded to it), the configured value, and the truth and RE where known."""
    header = ["parameter", "unit", "configured", "estimate ± 95 %", "95 % interval"]
    header += ["truth", "RE of mean %"] if res.truth is not None else []
    rows = []
    for row in parameter_rows(res):
        cells = [row.label, row.unit, significant(row.configured), row.with_interval, row.interval_text]
        rows.append(cells + ([row.truth_text, fixed(row.re_percent)] if res.truth is not None else []))
    return header, rows


def markdown(results: list[Campaign], files: list[str]) -> str:
    """Markdown: per training run, J on it and on the held-out runs; the real-time table; the estimates."""
    lines: list[str] = []
    groups: dict[str, list[tuple[Campaign, str]]] = {}
    for res, f in zip(results, files, strict=True):
        groups.setdefault(source(res), []).append((res, f))
    for src, members in groups.items():
        held = list(dict.fromkeys(Path(v).stem for res, _ in members for v, _ in res.findings.validation))
        lines += [f"#### Cost J (Eq. 7): trained on {src}", ""]
        header = ["result", "model", "unknowns", "J train"] + [f"J {h}" for h in held]
        if any(res.truth is not None for res, _ in members):
            header += ["J truth (noise floor)", "NRE of mean %"]
        rows = []
        for res, f in members:
            val = {Path(v).stem: j for v, j in res.findings.validation}
            row = [label(res, f), res.findings.model, str(len(res.names)), _J_train(res)] + [
                _g(val.get(h), ".4g") for h in held
            ]
            if "NRE of mean %" in header:
                row += [_g(_J_truth(res), ".4g"), _g(res.summary.nre_percent, ".3f")]
            rows.append(row)
        lines += _md(header, rows, right_from=2) + [""]
    lines += ["#### Real-time check: fixed-step RK4", ""]
    rows = []
    for res, f in zip(results, files, strict=True):
        rt = res.findings.realtime
        rows.append([
            label(res, f), res.findings.model, f"{1e3 * rt.dt:g}", "yes" if rt.stable else "**no**",
            f"{rt.realtime_factor:.0f}", f"{1e3 * rt.largest_stable_dt:.3g}",
        ])  # fmt: skip
    header = ["result", "model", "step [ms]", "stable", "real-time factor", "largest stable step [ms]"]
    lines += _md(header, rows, right_from=2) + [""]
    lines += ["#### Identified parameters", ""]
    for res, f in zip(results, files, strict=True):
        header, rows = estimates(res)
        evaluations = f"{np.mean(res.summary.evaluations):.0f} evaluations per run"
        lines += [f"`{label(res, f)}` ({res.findings.model}, {len(res.records)} run(s), {evaluations}; "
                  f"{interval_note(res)}):", ""]  # fmt: skip
        lines += _md(header, rows, right_from=2) + [""]
    return "\n".join(lines)


def latex(results: list[Campaign], files: list[str]) -> str:
    """LaTeX (booktabs): the identified parameters of each result, with J on its training and held-out runs."""
    parts: list[str] = []
    for res, f in zip(results, files, strict=True):
        header, rows = estimates(res)
        held = "; ".join(f"J {Path(v).stem} {j:.4g}" for v, j in res.findings.validation)
        caption = f"{label(res, f)}: {res.findings.model} on {source(res)}, J train {_J_train(res)}"
        parts += latex_table(header, rows, caption + (f"; {held}" if held else "") + f"; {interval_note(res)}")
    return "\n".join(parts)


def csv_text(results: list[Campaign], files: list[str]) -> str:
    """Long format: one row per result and unknown, the result's figures repeated on each row."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for res, f in zip(results, files, strict=True):
        rt, re = res.findings.realtime, res.summary.re_percent
        validation = ";".join(f"{Path(v).name}={j:.6g}" for v, j in res.findings.validation)
        for j, row in enumerate(parameter_rows(res)):
            writer.writerow([
                f, res.findings.model, res.data_file or "", len(res.records), row.name, row.unit,
                None if res.truth is None else row.truth, res.nominal[j], row.estimate, row.low, row.high,
                row.interval_from, row.at_bound, None if re is None else re[j], res.summary.sd[j],
                float(_J(res).mean()), None if res.truth is None else float(_J_truth(res)), validation, rt.dt,
                rt.stable, rt.realtime_factor, rt.largest_stable_dt, res.summary.wall_s,
            ])  # fmt: skip
    return buf.getvalue()


def json_text(results: list[Campaign], files: list[str]) -> str:
    return to_json([dict(r.to_json(), file=f) for r, f in zip(results, files, strict=True)])
