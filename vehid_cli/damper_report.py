"""Reports of damper results files (kind vehid.damper): terminal, Markdown, CSV and JSON tables.

Every number comes from the files: J (Fleps-Dezasse Eq. 7) on the training run and on each held-out run,
the estimates (with RE against the truth for synthetic data), and the real-time check.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np
from rich.table import Table

from .damper_campaign import DamperResult, result_json
from .results import to_json

CSV_COLUMNS = (
    "file", "model", "data_file", "runs", "parameter", "truth", "start", "mean", "re_percent", "sd",
    "J_train", "J_truth", "validation_J", "rt_dt_s", "rt_stable", "rt_factor", "rt_largest_stable_dt_s", "wall_s",
)  # fmt: skip


def _g(value, fmt: str = ".6g") -> str:
    return "–" if value is None or not np.isfinite(value) else f"{value:{fmt}}"


def label(res: DamperResult, file: str) -> str:
    """How a result is named in tables and legends: the results file's stem."""
    return Path(file).stem


def source(res: DamperResult) -> str:
    if res.data_file:
        return Path(res.data_file).name
    b = res.config.bench
    return f"synthetic {b.excitation}, noise {100 * res.config.noise.level:g} %"


def _J_train(res: DamperResult) -> str:
    J = res.J
    return _g(J[0], ".4g") if J.size == 1 else f"{J.mean():.4g} (± {J.std(ddof=1):.2g})"


def parameter_table(res: DamperResult, file: str) -> Table:
    """Rich table of one result: per unknown truth, start, estimate (mean over runs), RE, spread."""
    algorithm = res.config.identify.algorithm.name
    title = f"{label(res, file)} · {res.model} · {source(res)} · {len(res.runs)} run(s) · {algorithm}"
    table = Table(title=title, title_justify="left")
    for col in ("parameter", "truth", "configured", "estimate", "RE %", "sd over runs"):
        table.add_column(col, justify="left" if col == "parameter" else "right")
    re = res.re_percent
    for j, name in enumerate(res.names):
        table.add_row(
            name, _g(None if res.truth is None else res.truth[j]), _g(res.start[j]), _g(res.mean[j]),
            _g(None if re is None else re[j], ".3f"), _g(res.sd[j]) if len(res.runs) > 1 else "–",
        )  # fmt: skip
    rt = res.realtime
    parts = [f"J train {_J_train(res)}"]
    if res.truth is not None:
        parts.append(f"J of the truth (noise floor) {res.J_truth.mean():.4g}")
        parts.append(f"NRE of mean {_g(res.nre_percent, '.3f')} %")
    parts += [f"J {Path(f).stem} {j:.4g}" for f, j in res.validation]
    parts.append(
        f"RK4 at {1e3 * rt.dt:g} ms {'stable' if rt.stable else 'UNSTABLE'}, "
        f"real-time factor {rt.realtime_factor:.0f}, "
        f"largest stable step {1e3 * rt.largest_stable_dt:.3g} ms"
    )
    parts.append(f"evaluations/run {np.mean([r.evaluations for r in res.runs]):.0f} · wall {res.wall_s:.1f} s")
    table.caption = " · ".join(parts)
    table.caption_justify = "left"
    return table


def _md(header: list[str], rows: list[list[str]], right_from: int = 1) -> list[str]:
    align = ["---" if i < right_from else "---:" for i in range(len(header))]
    return ["| " + " | ".join(header) + " |", "| " + " | ".join(align) + " |"] + [
        "| " + " | ".join(r) + " |" for r in rows
    ]


def markdown(results: list[DamperResult], files: list[str]) -> str:
    """Markdown: per training run, J on it and on the held-out runs; the real-time table; the estimates."""
    lines: list[str] = []
    groups: dict[str, list[tuple[DamperResult, str]]] = {}
    for res, f in zip(results, files, strict=True):
        groups.setdefault(source(res), []).append((res, f))
    for src, members in groups.items():
        held = list(dict.fromkeys(Path(v).stem for res, _ in members for v, _ in res.validation))
        lines += [f"#### Cost J (Eq. 7): trained on {src}", ""]
        header = ["result", "model", "unknowns", "J train"] + [f"J {h}" for h in held]
        if any(res.truth is not None for res, _ in members):
            header += ["J truth (noise floor)", "NRE of mean %"]
        rows = []
        for res, f in members:
            val = {Path(v).stem: j for v, j in res.validation}
            row = [label(res, f), res.model, str(len(res.names)), _J_train(res)] + [_g(val.get(h), ".4g") for h in held]
            if "NRE of mean %" in header:
                row += [_g(res.J_truth.mean(), ".4g"), _g(res.nre_percent, ".3f")]
            rows.append(row)
        lines += _md(header, rows, right_from=2) + [""]
    lines += ["#### Real-time check: fixed-step RK4", ""]
    rows = []
    for res, f in zip(results, files, strict=True):
        rt = res.realtime
        rows.append([
            label(res, f), res.model, f"{1e3 * rt.dt:g}", "yes" if rt.stable else "**no**", f"{rt.realtime_factor:.0f}",
            f"{1e3 * rt.largest_stable_dt:.3g}",
        ])  # fmt: skip
    header = ["result", "model", "step [ms]", "stable", "real-time factor", "largest stable step [ms]"]
    lines += _md(header, rows, right_from=2) + [""]
    lines += ["#### Identified parameters (SI: N, m, s)", ""]
    for res, f in zip(results, files, strict=True):
        re = res.re_percent
        header = ["parameter", "configured", "estimate"] + (["truth", "RE of mean %"] if res.truth is not None else [])
        rows = []
        for j, name in enumerate(res.names):
            row = [name, _g(res.start[j]), _g(res.mean[j])]
            if res.truth is not None:
                row += [_g(res.truth[j]), _g(re[j], ".3f")]
            rows.append(row)
        lines += [f"`{label(res, f)}` ({res.model}, {len(res.runs)} run(s), "
                  f"{np.mean([r.evaluations for r in res.runs]):.0f} evaluations per run):", ""]  # fmt: skip
        lines += _md(header, rows) + [""]
    return "\n".join(lines)


def csv_text(results: list[DamperResult], files: list[str]) -> str:
    """Long format: one row per result and unknown, the result's figures repeated on each row."""
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for res, f in zip(results, files, strict=True):
        rt, re = res.realtime, res.re_percent
        validation = ";".join(f"{Path(v).name}={j:.6g}" for v, j in res.validation)
        for j, name in enumerate(res.names):
            writer.writerow([
                f, res.model, res.data_file or "", len(res.runs), name, None if res.truth is None else res.truth[j],
                res.start[j], res.mean[j], None if re is None else re[j], res.sd[j], float(res.J.mean()),
                None if res.truth is None else float(res.J_truth.mean()), validation, rt.dt, rt.stable,
                rt.realtime_factor, rt.largest_stable_dt, res.wall_s,
            ])  # fmt: skip
    return buf.getvalue()


def json_text(results: list[DamperResult], files: list[str]) -> str:
    return to_json([dict(result_json(r), file=f) for r, f in zip(results, files, strict=True)])
