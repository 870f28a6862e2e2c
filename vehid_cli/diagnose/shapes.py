"""The library's shapes of a strut force law and which effects they point to: each shape's curves over deflection
or velocity, the resemblance of an estimated curve to them (a one-parameter weighted least-squares fit, uncentred
R²: the curves all pass through 0), and the order in which an estimate's resemblance puts the candidates.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

ALPHA = 1e-3  # significance level below which candidate_order reorders (attribution's family-wise level)
GAS_L, GAS_KAPPA = 0.1, 1.4  # the library's gas_spring defaults [m], [-]
COULOMB_EPS, ASYM_EPS = 0.01, 0.02  # the library's coulomb_friction / asymmetric_damping v_eps [m/s]

# Shape -> the library effects (and parameter candidates) it points to, with an affinity in [0, 1].
# "{axle}" is filled with f / r. Secondary entries: a lagged damper adds stiffness, saturated Bouc-Wen
# hysteresis looks like friction (and like stiffness at small amplitude), a bump stop like stiffening.
SHAPE_EFFECTS: dict[str, tuple[tuple[str, float], ...]] = {
    "linear_stiffness": (("parameter:k{axle}", 1.0), ("damper_lag", 0.5), ("hysteresis", 0.4)),
    "progressive_spring": (("progressive_spring", 1.0), ("gas_spring", 0.5), ("backlash", 0.3)),
    "gas_spring": (("gas_spring", 1.0), ("progressive_spring", 0.5)),
    "dead_band": (("backlash", 1.0), ("progressive_spring", 0.5)),
    "linear_damping": (("parameter:c{axle}", 1.0), ("damper_lag", 0.3), ("tyre_damping", 0.3)),
    "coulomb_friction": (("coulomb_friction", 1.0), ("hysteresis", 0.7)),
    "asymmetric_damping": (("asymmetric_damping", 1.0),),
    "one_sided_damping": (("asymmetric_damping", 1.0),),
    "quadratic_damping": (("asymmetric_damping", 0.6),),
    "sqrt_damper": (("coulomb_friction", 0.7), ("hysteresis", 0.4)),
}
SHAPES = {
    "deflection": ("linear_stiffness", "progressive_spring", "gas_spring", "dead_band"),
    "velocity": (
        "linear_damping", "coulomb_friction", "asymmetric_damping", "one_sided_damping", "quadratic_damping",
        "sqrt_damper",
    ),
}  # fmt: skip


# ------------------------------------------------------------------------------------------ results


@dataclass(frozen=True)
class Resemblance:
    """How well each library shape, scaled by one least-squares amplitude, matches an estimated curve."""

    best: str
    r2: dict[str, float]  # uncentred weighted R² per shape (0 when the amplitude must have the other sign)
    amplitude: dict[str, float]  # fitted amplitude per shape [N per unit of the shape]
    detail: dict[str, str]  # how a profiled shape was chosen (dead band width, one-sided direction)

    def to_json(self) -> dict:
        return {"best": self.best, "r2": dict(self.r2), "amplitude": dict(self.amplitude), "detail": dict(self.detail)}


class EstimatedCurve(Protocol):
    """What candidate_order reads of one estimated curve (unexplained.Curve)."""

    chi2_explained: float
    resembles: Resemblance

    @property
    def significant(self) -> bool: ...


class AxleCurves(Protocol):
    """What candidate_order reads of one axle's estimate (unexplained.AxleEstimate)."""

    axle: str
    g: EstimatedCurve
    h: EstimatedCurve


class Estimate(Protocol):
    """What candidate_order reads of the non-parametric estimate (unexplained.Unexplained, whose module compares
    its curves with the shapes here and so imports this one)."""

    p_value: float
    front: AxleCurves
    rear: AxleCurves


# ------------------------------------------------------------------------------------------ shapes


def _shape_columns(variable: str, x: NDArray) -> dict[str, list[tuple[NDArray, int, str]]]:
    """Each shape's candidate curves over x: (curve, sign constraint of the amplitude (0: free), detail)."""
    xm = max(float(np.max(np.abs(x))), 1e-300)
    if variable == "deflection":
        u = np.maximum(x / GAS_L, -0.9)
        gas = (1.0 - (1.0 + u) ** (-GAS_KAPPA)) - GAS_KAPPA * u
        band = [(np.sign(x) * np.maximum(np.abs(x) - f * xm, 0.0), 1, f"dead band +-{f * xm:.4g} m")
                for f in (0.2, 0.4, 0.6)]  # fmt: skip
        return {
            "linear_stiffness": [(x, 0, "")],
            "progressive_spring": [(x**3, 1, "")],
            "gas_spring": [(gas, 1, f"L = {GAS_L} m, kappa = {GAS_KAPPA}")],
            "dead_band": band,
        }
    return {
        "linear_damping": [(x, 0, "")],
        "coulomb_friction": [(np.tanh(x / COULOMB_EPS), 1, f"v_eps = {COULOMB_EPS} m/s")],
        "asymmetric_damping": [(x * np.tanh(x / ASYM_EPS), 0, f"v tanh(v / {ASYM_EPS}) (the library's)")],
        "one_sided_damping": [(np.maximum(x, 0.0), 1, "rebound only"), (np.minimum(x, 0.0), 1, "compression only")],
        "quadratic_damping": [(np.abs(x) * x, 0, "")],
        "sqrt_damper": [(np.sign(x) * np.sqrt(np.abs(x)), 1, "")],
    }


def resemblance(variable: str, x: NDArray, f: NDArray, se: NDArray, free_line: bool = False) -> Resemblance:
    """Best one-parameter match of the library's shapes to the curve f(x) [N] with standard errors se [N];
    `free_line`: f is known modulo a line through 0 (and given without its projection on x), and so is each
    shape (a linear stiffness or damping then matches nothing)."""
    floor = 1e-2 * max(float(np.median(se[se > 0])) if np.any(se > 0) else 1.0, 1e-300)
    w = 1.0 / np.maximum(se, floor) ** 2
    total = float(np.sum(w * f * f))
    r2, amp, detail = {}, {}, {}
    for name, options in _shape_columns(variable, x).items():
        best = (-np.inf, 0.0, "")
        for s, sign, text in options:
            if free_line:
                s = s - x * float(x @ s) / float(x @ x)
            ss = float(np.sum(w * s * s))
            a = float(np.sum(w * f * s)) / ss if ss > 0 else 0.0
            if sign and a * sign < 0:
                a = 0.0
            q = 1.0 - float(np.sum(w * (f - a * s) ** 2)) / total if total > 0 else 0.0
            if q > best[0]:
                best = (q, a, text)
        r2[name], amp[name] = float(best[0]), float(best[1])
        if best[2]:
            detail[name] = best[2]
    top = max(r2, key=lambda k: r2[k])
    return Resemblance(top, r2, amp, detail)


def candidate_order(unexplained: Estimate, effect_names: Sequence[str], alpha: float = ALPHA) -> list[str]:
    """`effect_names` (library effects and ``parameter:kf``-style candidates) ordered best first by how well the
    significant estimated curves resemble each one's shape (R² x affinity of the shape to the effect, weighted by
    the residual power each curve explains); names the estimate does not point to keep their order after the
    others. Unchanged when the estimate is not significant (p >= alpha)."""
    names = list(effect_names)
    if not unexplained.p_value < alpha:
        return names
    score = {name: 0.0 for name in names}
    total = sum(c.chi2_explained for a in (unexplained.front, unexplained.rear) for c in (a.g, a.h)) or 1.0
    for a in (unexplained.front, unexplained.rear):
        tag = a.axle[0]
        for c in (a.g, a.h):
            if not c.significant:
                continue
            weight = c.chi2_explained / total
            for shape, r2 in c.resembles.r2.items():
                for effect, affinity in SHAPE_EFFECTS[shape]:
                    effect = effect.format(axle=tag)
                    if effect in score:
                        score[effect] = max(score[effect], weight * max(r2, 0.0) * affinity)
    return sorted(names, key=lambda e: (-score[e], names.index(e)))
