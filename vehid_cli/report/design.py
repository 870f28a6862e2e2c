"""`vehid design` output: the comparison tables (rich and Markdown), the JSON document, the figures and the designed
config as YAML. Every number comes from a `design.DesignResult`."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from rich.table import Table

from .. import __version__
from ..core.figures import plt, save
from ..core.files import atomic_path
from ..core.jsonio import finite_or_none
from ..design import LABELS, DesignResult, Evaluation, Plan

CRITERION_TEXT = {"nre": "NRE bound [%]", "d_optimal": "-log det F", "worst": "largest bound [%]"}


def _num(value: float, fmt: str = ".3g") -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "–"
    if math.isinf(value):
        return "∞"
    return f"{value:{fmt}}"


def criterion_label(criterion: str) -> str:
    kind, _, name = criterion.partition(":")
    return f"bound of {name} [%]" if name else CRITERION_TEXT[kind]


def _identifiable(e: Evaluation) -> str:
    lost = e.bound.unidentifiable()
    return "yes" if not lost else f"no ({', '.join(lost)})"


def comparison_rows(r: DesignResult) -> list[list[str]]:
    """Rows: per-parameter bound, NRE bound, condition, identifiable, criterion; configured, designed, factor."""
    c, d = r.configured.bound, r.designed.bound
    rows = [
        [f"bound {n} [%]", _num(a), _num(b), _num(f, ".3g")]
        for n, a, b, f in zip(c.names, c.re_sd_percent, d.re_sd_percent, r.parameter_improvement, strict=True)
    ]
    rows.append(["NRE bound [%]", _num(c.nre_rms_percent), _num(d.nre_rms_percent), _num(r.nre_improvement)])
    rows.append(["condition", _num(c.condition), _num(d.condition), ""])
    rows.append(["identifiable", _identifiable(r.configured), _identifiable(r.designed), ""])
    if not r.criterion.startswith("nre"):
        rows.append([f"criterion: {criterion_label(r.criterion)}", _num(r.configured.criterion),
                     _num(r.designed.criterion), _num(r.improvement)])  # fmt: skip
    return rows


def plan_rows(r: DesignResult) -> list[list[str]]:
    """Rows: the test's variables, configured and designed, and the limits of design:."""
    c, d = r.configured.plan, r.designed.plan
    design = r.configured.config.design
    lim = {
        "speed": design.speed_kmh, "length": design.length, "duration": design.duration,
    }  # fmt: skip

    def span(pair) -> str:
        return "fixed" if pair is None else f"{pair[0]:g} – {pair[1]:g}"

    heights = design.heights
    rows = [
        ["speed [km/h]", f"{c.speed_kmh:.3g}", f"{d.speed_kmh:.3g}", span(lim["speed"])],
        ["heights 1..4 [cm]", _cm(c), _cm(d), "fixed" if heights is None else f"{100 * heights.min:g} – "
                                                                             f"{100 * heights.max:g}"],
        ["ratio b2/b1", f"{c.side_ratio:.3g}", f"{d.side_ratio:.3g}", ""],
        ["shape", c.shape, d.shape, ", ".join(design.shapes) if design.shapes else "fixed"],
        ["length [m]", f"{c.length:.3g}", f"{d.length:.3g}", span(lim["length"])],
        ["duration [s]", f"{c.duration:.3g}", f"{d.duration:.3g}", span(lim["duration"])],
    ]  # fmt: skip
    if d.sensors is not None:
        configured = ", ".join(r.configured.config.sensor_layout().channel_names)
        rows.append(["sensors", configured, ", ".join(d.sensors), f"{design.sensors.count} of "
                                                                    f"{len(design.sensors.candidates)}"])  # fmt: skip
    return rows


def _cm(plan: Plan) -> str:
    return " ".join(f"{100 * h:.3g}" for h in plan.heights)


def verification_rows(r: DesignResult) -> list[list[str]]:
    v = r.verification
    if v is None:
        return []
    return [
        ["configured", f"{v.configured_nre_rms:.3g}", f"{v.configured_bound:.3g}", f"{v.configured_ratio:.2f}"],
        ["designed", f"{v.designed_nre_rms:.3g}", f"{v.designed_bound:.3g}", f"{v.designed_ratio:.2f}"],
    ]


def notes(r: DesignResult) -> list[str]:
    """The sentences under the tables: improvement, what the configured test cannot identify and the cheapest
    changes that fix it, the noise's consequence, the search's cost."""
    out = []
    if r.unidentifiable:
        out.append(f"the configured test cannot identify {', '.join(r.unidentifiable)}")
        for i, p in enumerate(r.proposals):
            lead = "cheapest change" if i == 0 else "or"
            out.append(f"  {lead}: {p.text} makes {', '.join(p.identifies)} identifiable "
                       f"(NRE bound {p.nre_rms_percent:.3g} %)")  # fmt: skip
        if not r.proposals:
            out.append("  no single change within the design limits makes them identifiable")
    else:
        out.append(
            f"the designed test lowers the NRE bound {r.nre_improvement:.3g}x "
            f"({r.configured.bound.nre_rms_percent:.3g} % -> {r.designed.bound.nre_rms_percent:.3g} %)"
        )
    if r.verification is not None:
        v = r.verification
        out.append(
            f"verified over {v.runs} runs: achieved per-run NRE RMS / bound {v.configured_ratio:.2f} (configured), "
            f"{v.designed_ratio:.2f} (designed); achieved improvement {v.achieved_factor:.3g}x"
        )
    out.append(r.noise_note)
    out.append(f"{r.evaluations} bounds evaluated in {r.wall_s:.1f} s on {r.jobs} process(es)")
    return out


def rich_tables(r: DesignResult) -> list[Table]:
    tables = []
    t = Table(title=f"vehid design · criterion {r.criterion}", title_justify="left")
    for col in ("", "configured", "designed", "factor"):
        t.add_column(col, justify="left" if not col else "right")
    for row in comparison_rows(r):
        t.add_row(*row)
    tables.append(t)
    t = Table(title="the test", title_justify="left")
    for col in ("", "configured", "designed", "limits"):
        t.add_column(col, justify="left" if not col else "right")
    for row in plan_rows(r):
        t.add_row(*row)
    tables.append(t)
    if r.verification is not None:
        t = Table(title=f"verification: {r.verification.runs}-run campaigns", title_justify="left")
        for col in ("test", "per-run NRE RMS [%]", "bound [%]", "ratio"):
            t.add_column(col, justify="left" if col == "test" else "right")
        for row in verification_rows(r):
            t.add_row(*row)
        tables.append(t)
    return tables


def _md(header: list[str], rows: list[list[str]]) -> list[str]:
    out = ["| " + " | ".join(header) + " |", "|" + "|".join(["---"] + ["---:"] * (len(header) - 1)) + "|"]
    return out + ["| " + " | ".join(row) + " |" for row in rows]


def markdown(r: DesignResult) -> str:
    """The tables and notes as Markdown (docs/results/design.md)."""
    lines = _md(["", "configured", "designed", "factor"], comparison_rows(r)) + [""]
    lines += _md(["", "configured", "designed", "limits"], plan_rows(r)) + [""]
    if r.verification is not None:
        lines += _md(["test", "per-run NRE RMS [%]", "bound [%]", "ratio"], verification_rows(r)) + [""]
    lines += [f"- {n.strip()}" for n in notes(r)]
    return "\n".join(lines) + "\n"


# ------------------------------------------------------------------------------------------ JSON


def _bound_json(e: Evaluation, names) -> dict:
    b = e.bound
    return {
        "test": e.plan.to_json(),
        "re_sd_percent": {n: finite_or_none(v) for n, v in zip(names, b.re_sd_percent, strict=True)},
        "nre_rms_percent": finite_or_none(b.nre_rms_percent),
        "condition": finite_or_none(b.condition),
        "identifiable": {n: bool(v) for n, v in zip(names, b.identifiable, strict=True)},
        "log_det_fisher": finite_or_none(e.log_det),
        "criterion": finite_or_none(e.criterion),
    }


def design_json(r: DesignResult, output: str | None = None) -> dict:
    """The `vehid design --json` document (docs/design.md)."""
    names = list(r.configured.bound.names)
    cfg = r.configured.config
    v = r.verification
    return {
        "kind": "vehid.design",
        "vehid_version": __version__,
        "config": cfg.source,
        "output": output,
        "criterion": r.criterion,
        "unknowns": names,
        "noise": cfg.noise.describe(),
        "noise_note": r.noise_note,
        "limits": cfg.design.model_dump(mode="json", exclude_none=True),
        "variables": list(r.space.free),
        "configured": _bound_json(r.configured, names),
        "designed": _bound_json(r.designed, names),
        "improvement": {
            "criterion": finite_or_none(r.improvement),
            "nre": finite_or_none(r.nre_improvement),
            "per_parameter": {n: finite_or_none(f) for n, f in zip(names, r.parameter_improvement, strict=True)},
        },
        "unidentifiable": list(r.unidentifiable),
        "proposals": [
            {
                "variable": p.variable,
                "value": finite_or_none(p.value),
                "sensors": None if p.sensors is None else list(p.sensors),
                "text": p.text,
                "change": p.change,
                "nre_rms_percent": finite_or_none(p.nre_rms_percent),
                "identifies": list(p.identifies),
            }
            for p in r.proposals
        ],  # fmt: skip
        "sweeps": [
            {
                "variable": p.variable,
                "through": p.through,
                "values": p.values.tolist(),
                "criterion": p.criterion.tolist(),
                "nre_rms_percent": p.nre.tolist(),
            }
            for p in r.sweeps
        ],  # fmt: skip
        "search": {
            "evaluations": r.evaluations,
            "wall_s": r.wall_s,
            "jobs": r.jobs,
            "seed": cfg.design.search.seed,
        },  # fmt: skip
        "verify": None
        if v is None
        else {
            "runs": v.runs,
            "configured": {
                "per_run_nre_rms": v.configured_nre_rms,
                "crlb_nre_rms_percent": v.configured_bound,
                "ratio": v.configured_ratio,
            },
            "designed": {
                "per_run_nre_rms": v.designed_nre_rms,
                "crlb_nre_rms_percent": v.designed_bound,
                "ratio": v.designed_ratio,
            },
            "achieved_improvement": v.achieved_factor,
        },  # fmt: skip
    }


# ------------------------------------------------------------------------------------------ files


def write_config(r: DesignResult, path: str | Path) -> None:
    """The designed test as a ready config (the configured config with the designed road, duration and sensors)."""
    d = r.designed
    header = (
        f"# Designed by vehid {__version__} (vehid design {r.configured.config.source}, criterion {r.criterion}):\n"
        f"# NRE bound {d.bound.nre_rms_percent:.4g} % against {r.configured.bound.nre_rms_percent:.4g} % for the "
        "configured test.\n"
    )
    with atomic_path(path) as tmp:
        tmp.write_text(header + d.config.to_yaml())


FIGURES = {
    "speed_kmh": ("design_speed.png", "speed [km/h]"),
    "side": ("design_ratio.png", "height ratio, lower side / higher side"),
}


def write_plots(r: DesignResult, directory: str | Path) -> list[Path]:
    """The criterion against speed and against the left/right height ratio, the other variables at the designed
    optimum and at the configured test; the two tests marked."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    written = []
    for name, (filename, xlabel) in FIGURES.items():
        profiles = [p for p in r.sweeps if p.variable == name]
        if not profiles:
            continue
        fig, ax = plt.subplots(figsize=(7, 4.5), constrained_layout=True)
        for p, style in zip(profiles, ("-", "--"), strict=False):
            y = np.where(np.isfinite(p.criterion), p.criterion, np.nan)
            ax.plot(p.values, y, style, marker=".", label=f"others as {p.through}")
        for e, mark, label in ((r.designed, "*", "designed"), (r.configured, "o", "configured")):
            x = e.plan.speed_kmh if name == "speed_kmh" else min(e.plan.side_ratio, 1 / e.plan.side_ratio)
            if math.isfinite(e.criterion):
                ax.plot([x], [e.criterion], mark, ms=12, label=f"{label} test")
        if r.criterion.startswith(("nre", "worst")):
            ax.set_yscale("log")
        ax.set_xlabel(xlabel)
        ax.set_ylabel(criterion_label(r.criterion))
        ax.set_title(f"{LABELS[name]}: {criterion_label(r.criterion)} (gaps: not identifiable)", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        path = directory / filename
        save(fig, path)
        written.append(path)
    return written
