"""`vehid design` output for a test designed through the system's design variables (the rigs): the comparison
table, the JSON document and the designed config as YAML. Every number comes from a `design.VariableDesign`."""

from __future__ import annotations

from pathlib import Path

from rich.markup import escape
from rich.table import Table

from .. import __version__
from ..core.files import atomic_path
from ..core.jsonio import finite_or_none
from ..design.variables import VariableDesign
from .design import _num, criterion_label


def rows(r: VariableDesign) -> list[list[str]]:
    """Rows: each variable (configured, designed, range), each bound, the NRE bound and the criterion."""
    out = [[f"{k} [{u}]", _num(c, ".4g"), _num(d, ".4g"), f"{lo:.4g} – {hi:.4g}"]
           for k, u, c, d, lo, hi in zip(r.keys, r.units, r.configured_values, r.designed_values, r.lower, r.upper,
                                         strict=True)]  # fmt: skip
    c, d = r.configured, r.designed
    out += [[f"bound {n} [%]", _num(a), _num(b), ""] for n, a, b in zip(c.names, c.re_sd_percent, d.re_sd_percent,
                                                                        strict=True)]  # fmt: skip
    out.append(["NRE bound [%]", _num(c.nre_rms_percent), _num(d.nre_rms_percent), ""])
    if not r.criterion.startswith("nre"):
        out.append([f"criterion: {criterion_label(r.criterion)}", _num(r.configured_criterion),
                    _num(r.designed_criterion), ""])  # fmt: skip
    return out


def rich_table(r: VariableDesign) -> Table:
    t = Table(title=f"vehid design · criterion {r.criterion}", title_justify="left")
    for col in ("", "configured", "designed", "range"):
        t.add_column(col, justify="left" if not col else "right")
    for row in rows(r):
        t.add_row(*(escape(c) for c in row))
    return t


def notes(r: VariableDesign) -> list[str]:
    return [f"criterion improved by {_num(r.improvement)}x; {r.evaluations} bounds in {r.wall_s:.1f} s"]


def design_json(r: VariableDesign, output: str | None = None) -> dict:
    """The comparison as a JSON document."""

    def test(values, bound, criterion) -> dict:
        return {
            "values": {k: float(v) for k, v in zip(r.keys, values, strict=True)},
            "criterion": finite_or_none(criterion), "nre_bound_percent": finite_or_none(bound.nre_rms_percent),
            "bounds_percent": {n: finite_or_none(float(v)) for n, v in zip(bound.names, bound.re_sd_percent,
                                                                          strict=True)},
            "identifiable": bool(all(bound.identifiable)),
        }  # fmt: skip

    return {
        "vehid": __version__, "criterion": r.criterion,
        "variables": [{"key": k, "unit": u, "range": [float(lo), float(hi)]}
                      for k, u, lo, hi in zip(r.keys, r.units, r.lower, r.upper, strict=True)],
        "configured": test(r.configured_values, r.configured, r.configured_criterion),
        "designed": test(r.designed_values, r.designed, r.designed_criterion),
        "improvement": finite_or_none(r.improvement), "evaluations": r.evaluations, "config": output,
    }  # fmt: skip


def write_config(r: VariableDesign, source: str, path: str | Path) -> None:
    """The designed test as a ready config."""
    header = (
        f"# Designed by vehid {__version__} (vehid design {source}, criterion {r.criterion}): NRE bound "
        f"{r.designed.nre_rms_percent:.4g} % against {r.configured.nre_rms_percent:.4g} % configured.\n"
    )
    with atomic_path(path) as tmp:
        tmp.write_text(header + r.designed_config.to_yaml())
