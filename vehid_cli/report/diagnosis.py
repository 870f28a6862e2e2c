"""The tables of `vehid diagnose`: the first round's candidates and the model before and after, within 80 columns;
and its figures with a clear error when their directory cannot be written."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rich import box
from rich.console import Group
from rich.markup import escape
from rich.table import Table

from ..core.digits import significant, with_uncertainty
from ..core.errors import InputError, WriteFailed


def diagnosis_tables(result):
    """The candidate table (round 1) and the before/after table of a diagnosis, each within 80 columns; estimates
    with their units, rounded to their 95 % intervals."""
    claimed = set(result.selected)
    vname = "val. J" if result.validation_from_file else "held-out J"
    table = Table(
        title=f"candidates, round 1 (alpha = {result.alpha:g}, Bonferroni)", box=box.SIMPLE_HEAD,
        caption="accepted: significant (p < alpha / candidates) and lowers the " + vname
        + "; claimed: in the final model; screened: not fitted, its LR is its score statistic; stopped: its fit "
        "stopped after two steps, it cannot win the round (its LR a lower bound)",
    )  # fmt: skip
    for col in ("candidate", "k", "LR", "p", "J", vname, "status"):
        table.add_column(col, no_wrap=True, justify="left" if col in ("candidate", "status") else "right")
    for r in result.rounds[0] if result.rounds else ():
        status = "claimed" if r.effect in claimed else "stopped" if r.stopped else "screened" if r.screened else "-"
        status = "accepted" if status == "-" and r.accepted else status
        table.add_row(
            r.effect, str(r.k), f"{r.statistic:.3g}", f"{r.p_value:.2g}", f"{r.J:.4g}", f"{r.validation_J:.4g}", status
        )  # fmt: skip
    ba = Table(title="before / after (J: " + result.J_definition.split(":")[0] + ")", box=box.SIMPLE_HEAD)
    for col in ("", "before", "after"):
        ba.add_column(col, no_wrap=col == "")

    def fmt(v):
        return "-" if v is None else f"{v:.4g}"

    def est(rep, j):  # rounded to its 95 % interval (core.digits)
        if rep.names[j] in rep.fixed:
            return f"{significant(rep.x[j], 5)} (fixed)"
        return with_uncertainty(rep.x[j], rep.ci[j])

    b, a = result.before, result.after
    ba.add_row("model", ", ".join(b.effects) or "(declared)", ", ".join(a.effects) or "(nothing added)")
    ba.add_row("J", fmt(b.J), fmt(a.J))
    ba.add_row("residual / noise power", fmt(b.chi2_per_sample), fmt(a.chi2_per_sample))
    ba.add_row(vname, fmt(b.validation_J), fmt(a.validation_J))
    ba.add_row("NRE [%]", fmt(b.nre_percent), fmt(a.nre_percent))
    for j, name in enumerate(a.names):
        unit = result.units.get(name, "")
        label = escape(f"{name} [{unit}]" if unit else name)  # not rich markup
        ba.add_row(label, est(b, b.names.index(name)) if name in b.names else "-", est(a, j))
    if getattr(a, "ci_misfit", None) is not None:  # the model is wrong: intervals that survive the misfit, marked
        for j, name in enumerate(a.names):
            ba.add_row(escape(f"{name} 95 % (misfit)"), "", "-" if not np.isfinite(a.ci_misfit[j]) else
                       f"{a.x[j]:.5g} ± {a.ci_misfit[j]:.2g}")  # fmt: skip
    mu = getattr(result, "model_uncertainty", None)
    marks = ["estimates ± 95 % assuming the model right"]
    if getattr(a, "ci_misfit", None) is not None:
        marks.append("(misfit): 95 % surviving the misfit (sandwich)")
    if mu is not None and mu.imitates:  # the intervals that cover the explanations' spread, marked as such
        for name, lo, hi in zip(mu.names, mu.low, mu.high, strict=True):
            ba.add_row(escape(f"{name} 95 % (model unc.)"), "", f"[{lo:.5g}, {hi:.5g}]")
        marks.append("(model unc.): 95 % covering the library terms and the non-parametric force")
    if len(marks) > 1:
        ba.caption = escape("; ".join(marks))
    return Group(table, ba)


def plot_diagnosis_files(result, directory: Path, stem: str) -> list[Path]:
    """The diagnosis figures, with a clear error if the directory cannot be written (a full disk stays DiskFull, a
    refused write WriteFailed). Matplotlib is imported here, when figures are asked for: it costs `vehid diagnose`
    about 0.35 s of start-up otherwise (the tables need only rich)."""
    from .diagnose_plots import plot_diagnosis

    try:
        return plot_diagnosis(result, directory, stem)
    except WriteFailed:  # a full disk or a refused write: its own message
        raise
    except OSError as exc:
        raise InputError(f"cannot write figures: {exc.strerror}", source=str(directory)) from None
