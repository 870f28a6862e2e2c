"""Tables of damper campaigns (campaign files with system = damper): terminal, Markdown, CSV and JSON.

Every number comes from the files: J (Fleps-Dezasse Eq. 7) on the training run and on each held-out run,
the estimates (with RE against the truth for synthetic data), and the real-time check.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
from rich.table import Table

from ...core.jsonio import to_json
from ...identify.records import Campaign

CSV_COLUMNS = (
    "file", "model", "data_file", "runs", "parameter", "truth", "start", "mean", "re_percent", "sd",
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
    """Rich table of one result: per unknown truth, start, estimate (mean over runs), RE, the spread over runs (or,
    for one fit, its 95 % interval from the bound at the estimate) and the Cramér–Rao bound."""
    algorithm = res.config.identify.algorithm.name
    title = f"{label(res, file)} · {res.findings.model} · {source(res)} · {len(res.records)} run(s) · {algorithm}"
    table = Table(title=title, title_justify="left")
    single = len(res.records) == 1
    spread = "± 95 % (bound)" if single else "sd over runs %"
    for col in ("parameter", "truth", "configured", "estimate", "RE %", spread, "CRLB sd %"):
        table.add_column(col, justify="left" if col == "parameter" else "right")
    re, b, at_bound = res.summary.re_percent, res.bound, res.at_bound
    for j, name in enumerate(res.names):
        spread = _g(1.96 * b.sd[j], ".3g") if single else _g(res.summary.re_sd_percent[j], ".3f")
        if name in at_bound:  # the optimum lies beyond the box: no interval means anything
            spread = "on bound" if single else f"{spread} (at a bound in {at_bound[name]} runs)"
        row_name = name + (" AT BOUND" if name in at_bound and single else "")
        table.add_row(
            row_name, _g(None if res.truth is None else res.truth[j]), _g(res.nominal[j]), _g(res.summary.mean[j]),
            _g(None if re is None else re[j], ".3f"), spread, _g(b.re_sd_percent[j], ".3f"),
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
    table.caption = " · ".join(parts)
    table.caption_justify = "left"
    return table


def _md(header: list[str], rows: list[list[str]], right_from: int = 1) -> list[str]:
    align = ["---" if i < right_from else "---:" for i in range(len(header))]
    return ["| " + " | ".join(header) + " |", "| " + " | ".join(align) + " |"] + [
        "| " + " | ".join(r) + " |" for r in rows
    ]


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
    lines += ["#### Identified parameters (SI: N, m, s)", ""]
    for res, f in zip(results, files, strict=True):
        re = res.summary.re_percent
        header = ["parameter", "configured", "estimate"] + (["truth", "RE of mean %"] if res.truth is not None else [])
        rows = []
        for j, name in enumerate(res.names):
            row = [name, _g(res.nominal[j]), _g(res.summary.mean[j])]
            if res.truth is not None:
                row += [_g(res.truth[j]), _g(re[j], ".3f")]
            rows.append(row)
        lines += [f"`{label(res, f)}` ({res.findings.model}, {len(res.records)} run(s), "
                  f"{np.mean(res.summary.evaluations):.0f} evaluations per run):", ""]  # fmt: skip
        lines += _md(header, rows) + [""]
    return "\n".join(lines)


def csv_text(results: list[Campaign], files: list[str]) -> str:
    """Long format: one row per result and unknown, the result's figures repeated on each row."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for res, f in zip(results, files, strict=True):
        rt, re = res.findings.realtime, res.summary.re_percent
        validation = ";".join(f"{Path(v).name}={j:.6g}" for v, j in res.findings.validation)
        for j, name in enumerate(res.names):
            truth = None if res.truth is None else res.truth[j]
            writer.writerow([
                f, res.findings.model, res.data_file or "", len(res.records), name, truth, res.nominal[j],
                res.summary.mean[j], None if re is None else re[j], res.summary.sd[j], float(_J(res).mean()),
                None if res.truth is None else float(_J_truth(res)), validation, rt.dt, rt.stable,
                rt.realtime_factor, rt.largest_stable_dt, res.summary.wall_s,
            ])  # fmt: skip
    return buf.getvalue()


def json_text(results: list[Campaign], files: list[str]) -> str:
    return to_json([dict(r.to_json(), file=f) for r, f in zip(results, files, strict=True)])
