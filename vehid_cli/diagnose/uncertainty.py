"""Model uncertainty: when library terms only imitate a law they do not contain.

A strut whose damping grows with the square root of the velocity is outside the library, yet Coulomb friction, a
stiffer rear damper and asymmetric damping together fit it to the noise, and bias the declared unknowns (4.8 % NRE,
far outside their intervals). Two signs that the selected explanation is such an imitation:

* several library terms on one element of the strut (IMITATION_TERMS or more on its deflection law or on its
  velocity law: an effect counts on the variables of its own shapes, a known spring or damper on its axle's
  deflection or velocity, `shapes.PARAMETER_AFFINITY`): the law has a shape none of them has alone;
* the other explanation of the same residual, the non-parametric strut force F(d, v) = g(d) + h(v) per axle fitted
  jointly with the declared unknowns (`unexplained.py`), puts the declared unknowns elsewhere: farther apart than
  the two fits' 95 % intervals together (sqrt(ci_a² + ci_b²)). Judged on the unknowns outside the strut's law
  (`judged`): the struts' own spring and damper rates mean different things in the two explanations (the linear
  part of a law the non-parametric force shares out with g and h), so a progressive spring the library does hold
  put kr 38 intervals apart on the four-post rig while every body parameter agreed; they are still reported), and
  with a Bonferroni threshold over the unknowns judged (`apart`: 1.31 intervals for five, 1.41 for nine).

The comparison is made when the terms crowd on one element, or when the two explanations fit about equally
(`fit_about_equally`: the non-parametric force fits the training data no worse than the selected terms, beyond what
chance gives a chi²(k) of the terms' k parameters at ALPHA; whatever the number of terms). A disagreement makes the
verdict "incomplete: library terms imitate a law they do not contain", and the declared unknowns' intervals are
widened to cover both explanations (`widened`: the final model's interval, from its misfit-robust sandwich where
that is wider, grown by the spread between the explanations on either side, joined with the alternative's: the
spread is model uncertainty, not sampling error); both reported, the widened ones marked as covering the model
uncertainty.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..core.result import Result
from ..models.effects import LIBRARY
from .shapes import PARAMETER_AFFINITY, all_shapes
from .tails import chi2_isf

IMITATION_TERMS = 2  # library terms on one element of the strut from which the explanation is compared
ALPHA = 0.05  # level at which one explanation fits the training data significantly better than the other
INTERVAL_ALPHA = 0.05  # the intervals compared are 95 % intervals
AXLE_SUFFIX = ("f", "r")


def elements_of(term: str) -> tuple[str, ...]:
    """The strut variables (deflection, velocity) a selected term acts on: an effect's own shapes' variables, a known
    spring's or damper's (the linear shapes' parameter affinity); none for anything else (a tyre, a mass)."""
    effect = LIBRARY.get(term)
    if effect is not None:
        return tuple(dict.fromkeys(s.variable for s in effect.shapes))
    variable = {s.name: s.variable for v in all_shapes().values() for s in v}
    out = []
    for shape, pairs in PARAMETER_AFFINITY.items():
        if any(term == name.format(axle=a) for name, _ in pairs for a in AXLE_SUFFIX):
            out.append(variable[shape])
    return tuple(out)


def apart(judged: int) -> float:
    """How many 95 % intervals (together) apart one of `judged` unknowns must be for the explanations to disagree:
    1 for one unknown, more for several (Bonferroni: each tested at 5 % / judged, so that agreeing explanations of a
    law the library holds are called apart in 5 % of cases, not in up to 5 % per unknown: a progressive spring's a1
    came out 1.01 intervals apart among five unknowns). In 95 % half-widths: z(2.5 % / judged) / z(2.5 %)."""
    n = max(int(judged), 1)
    return float(np.sqrt(chi2_isf(INTERVAL_ALPHA / n, 1) / chi2_isf(INTERVAL_ALPHA, 1)))


def strut_rates() -> frozenset[str]:
    """The struts' own linear spring and damper rates (kf, kr, cf, cr): the parameters of the linear shapes'
    affinity, per axle."""
    return frozenset(name.split(":", 1)[1].format(axle=a) for pairs in PARAMETER_AFFINITY.values()
                     for name, _ in pairs for a in AXLE_SUFFIX)  # fmt: skip


def crowded_element(selected: Sequence[str]) -> tuple[str, tuple[str, ...]] | None:
    """The strut variable with IMITATION_TERMS or more selected terms on it, and those terms (the most crowded)."""
    by: dict[str, list[str]] = {}
    for term in selected:
        for variable in elements_of(term):
            by.setdefault(variable, []).append(term)
    if not by:
        return None
    variable, terms = max(by.items(), key=lambda kv: len(kv[1]))
    return (variable, tuple(terms)) if len(terms) >= IMITATION_TERMS else None


@dataclass(frozen=True)
class ModelUncertainty(Result):
    """The declared unknowns under two explanations of one residual: the selected library terms and the
    non-parametric strut force; where they disagree beyond their intervals, intervals that cover both."""

    element: str  # the strut variable the terms crowd on
    terms: tuple[str, ...]
    names: tuple[str, ...]  # the declared unknowns
    selected: NDArray  # their estimates with the selected terms
    selected_ci: NDArray  # 95 % half-widths
    alternative: NDArray  # their estimates beside the non-parametric force
    alternative_ci: NDArray
    low: NDArray  # the widened 95 % interval, covering both explanations (`widened`)
    high: NDArray
    trigger: str = "crowded"  # why the explanations were compared: "crowded" (terms on one element), "equal fit"
    fit_gap: float | None = None  # R (J_alternative - J_selected): the alternative's excess chi² (negative: better)
    fit_margin: float | None = None  # the chi²(k) critical value at ALPHA the excess stays under (equal fit)

    @property
    def separation(self) -> NDArray:
        """|selected - alternative| over the two intervals together, per unknown (above 1: they disagree)."""
        both = np.hypot(self.selected_ci, self.alternative_ci)
        return np.abs(self.selected - self.alternative) / np.maximum(both, 1e-300)

    @property
    def judged(self) -> NDArray:
        """Which unknowns the disagreement is judged on: all but the struts' own rates (`strut_rates`), unless
        nothing else was declared."""
        outside = np.array([n not in strut_rates() for n in self.names], dtype=bool)
        return outside if outside.any() else np.ones(len(self.names), dtype=bool)

    @property
    def threshold(self) -> float:
        """The separation above which the explanations disagree (`apart`), for the number of unknowns judged."""
        return apart(int(np.count_nonzero(self.judged)))

    @property
    def imitates(self) -> bool:
        """Do the explanations move some judged declared unknown beyond their intervals (`threshold`)?"""
        return bool(np.any(self.separation[self.judged] > self.threshold))

    @property
    def worst(self) -> str:
        return self.names[int(np.argmax(np.where(self.judged, self.separation, -np.inf)))]

    def summary(self) -> str:
        """One clause for the verdict."""
        where = f" on the strut {self.element}" if self.element else ""
        better = self.fit_gap is not None and self.fit_margin is not None and self.fit_gap < -self.fit_margin
        how = {
            "crowded": "fit the residual",
            "equal fit": "fit worse than the non-parametric strut force" if better
            else "and the non-parametric strut force fit about equally",
        }[self.trigger]  # fmt: skip
        apart = float(np.max(self.separation[self.judged]))
        return (
            f"{', '.join(self.terms)}{where} {how}, but the non-parametric strut "
            f"force puts the declared unknowns elsewhere (up to {apart:.3g}x their intervals apart, {self.worst}); "
            "their 95 % intervals are widened to cover both"
        )

    def to_json(self) -> dict:
        def pairs(lo, hi):
            return {n: [float(a), float(b)] for n, a, b in zip(self.names, lo, hi, strict=True)}

        sel, alt = self.selected, self.alternative
        return {
            "reason": "library terms imitate a law they do not contain",
            "imitates": self.imitates,
            "trigger": self.trigger,
            "element": f"strut {self.element}" if self.element else None,
            "terms": list(self.terms),
            "fit_gap": self.fit_gap,
            "fit_margin": self.fit_margin,
            "selected": {"estimates": dict(zip(self.names, map(float, sel), strict=True)),
                         "ci95": pairs(sel - self.selected_ci, sel + self.selected_ci)},
            "non_parametric": {"estimates": dict(zip(self.names, map(float, alt), strict=True)),
                               "ci95": pairs(alt - self.alternative_ci, alt + self.alternative_ci)},
            "separation": dict(zip(self.names, map(float, self.separation), strict=True)),
            "judged_on": [n for n, j in zip(self.names, self.judged, strict=True) if j],
            "threshold": self.threshold,
            "ci95_model_uncertainty": pairs(self.low, self.high),
        }  # fmt: skip


def fit_about_equally(J_selected: float, k: int, unexplained) -> tuple[bool, float, float]:
    """Do the selected terms (training chi² per sample J_selected, k parameters beyond the declared model) and the
    non-parametric strut force (`unexplained`: its chi² per sample after, over its R samples) fit the training data
    about equally? The alternative's excess R (J_alt - J_sel) must stay under the chi²(k) critical value at ALPHA:
    no worse than chance makes k parameters' worth of chi² (an alternative that fits better counts, all the more).
    Returns (equal, excess, margin)."""
    gap = float(unexplained.samples * (unexplained.chi2_after - J_selected))
    margin = chi2_isf(ALPHA, max(int(k), 1))
    return bool(np.isfinite(gap) and gap <= margin), gap, margin


def widened(x: NDArray, wide: NDArray, alt: NDArray, alt_ci: NDArray) -> tuple[NDArray, NDArray]:
    """The 95 % interval covering two explanations: the selected estimate x (half-width `wide`) and the alternative
    alt (alt_ci). The spread s = |x - alt| is model uncertainty that neither's sampling interval holds, and the
    selected terms' bias is at least that large in an unknown direction: x ± (wide + s), joined with the alternative's
    own interval alt ± alt_ci. (The union of the two intervals alone misses a truth beyond both estimates: the weak
    square-root damper put m 2.4 and 2.5 intervals' widths beyond its two estimates, on the same side.)"""
    s = np.abs(x - alt)
    return np.minimum(x - wide - s, alt - alt_ci), np.maximum(x + wide + s, alt + alt_ci)


def compare_explanations(
    selected: Sequence[str],
    names: Sequence[str],
    x: NDArray,
    ci: NDArray,
    unexplained,
    ci_misfit: NDArray | None = None,
    fit: tuple[float, int] | None = None,
) -> ModelUncertainty | None:
    """The declared unknowns `names` = x (95 % half-widths ci) of the final model with the `selected` terms against
    the non-parametric explanation (`unexplained`: an Unexplained fitted with the declared unknowns as nuisance),
    when the selected terms crowd on one element of the strut, or (`fit` = (the final model's training J, its
    parameters beyond the declared ones)) when both explanations fit about equally; None when neither, nothing is
    selected or nothing to compare. The widened intervals take the final model's misfit intervals (`ci_misfit`,
    where the residual is above the noise) where they are wider than ci."""
    if not selected or unexplained is None or unexplained.unknowns is None or unexplained.dx_ci is None:
        return None
    crowd = crowded_element(selected)
    trigger, gap, margin = "crowded", None, None
    if fit is not None and getattr(unexplained, "samples", None):
        equal, gap, margin = fit_about_equally(fit[0], fit[1], unexplained)
        if crowd is None and equal:
            trigger = "equal fit"
    if crowd is None and trigger != "equal fit":
        return None
    idx = [list(unexplained.names).index(n) for n in names if n in unexplained.names]
    if len(idx) != len(names):
        return None
    x, ci = np.asarray(x, dtype=float), np.asarray(ci, dtype=float)
    alt, alt_ci = unexplained.unknowns[idx], unexplained.dx_ci[idx]
    if not (np.all(np.isfinite(ci)) and np.all(np.isfinite(alt_ci))):
        return None
    wide = ci if ci_misfit is None else np.fmax(ci, np.asarray(ci_misfit, dtype=float))
    low, high = widened(x, wide, alt, alt_ci)
    element, terms = crowd if crowd is not None else ("", tuple(selected))
    return ModelUncertainty(element, terms, tuple(names), x, ci, alt, alt_ci, low, high, trigger, gap, margin)


def compare_reports(selected: Sequence[str], names: Sequence[str], after, unexplained) -> ModelUncertainty | None:
    """compare_explanations for the declared unknowns `names` in the final model's report `after` (its names, x, ci,
    ci_misfit, and its training J and parameter count beyond `names` for the equal-fit test)."""
    if unexplained is None or not all(n in after.names for n in names):
        return None
    idx = [list(after.names).index(n) for n in names]
    misfit = None if after.ci_misfit is None else np.asarray(after.ci_misfit)[idx]
    k = len([n for n in after.names if n not in names and n not in after.fixed])
    return compare_explanations(selected, names, after.x[idx], after.ci[idx], unexplained, misfit, (after.J, k))
