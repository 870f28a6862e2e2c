"""The library's shapes of a strut force law and which effects they point to: each shape's curves over deflection
or velocity, the resemblance of an estimated curve to them (a one-parameter weighted least-squares fit, uncentred
R²: the curves all pass through 0), and which candidates an estimate's resemblance points to.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from ..core.result import Result
from ..models.effects import LIBRARY, Shape

VARIABLES = ("deflection", "velocity")

ALPHA = 1e-3  # significance level below which an estimate points to candidates (attribution's family-wise level)
POINT_SHARE = 0.5  # an estimate points to the candidates scoring at least this share of the best one's score

# Shapes no effect of the library owns: a linear stiffness or damping (a mis-set known spring or damper), and laws the
# library only approximates. The effects' own shapes, and which shapes point to which effect, come from the registry
# (`models.effects`: Effect.shapes, Effect.resembles).
GENERIC_SHAPES = (
    Shape("linear_stiffness", "deflection", lambda x: [(x, 0, "")], rank=0),
    Shape("linear_damping", "velocity", lambda x: [(x, 0, "")], rank=0),
    Shape("one_sided_damping", "velocity",
          lambda x: [(np.maximum(x, 0.0), 1, "rebound only"), (np.minimum(x, 0.0), 1, "compression only")], rank=3),
    Shape("quadratic_damping", "velocity", lambda x: [(np.abs(x) * x, 0, "")], rank=4),
    Shape("sqrt_damper", "velocity", lambda x: [(np.sign(x) * np.sqrt(np.abs(x)), 1, "")], rank=5),
)  # fmt: skip
# "{axle}" is filled with f / r: a linear curve points to the axle's own spring or damper
PARAMETER_AFFINITY = {
    "linear_stiffness": (("parameter:k{axle}", 1.0),),
    "linear_damping": (("parameter:c{axle}", 1.0),),
}


def all_shapes() -> dict[str, tuple[Shape, ...]]:
    """The shapes of each variable (deflection, velocity), the generic ones and every registered effect's, in rank
    order (ties go to the earlier)."""
    found = [*GENERIC_SHAPES, *(s for e in LIBRARY.values() for s in e.shapes)]
    return {v: tuple(sorted((s for s in found if s.variable == v), key=lambda s: s.rank)) for v in VARIABLES}


def shape_effects() -> dict[str, tuple[tuple[str, float], ...]]:
    """Shape -> the parameter candidates and library effects it points to, with an affinity in [0, 1]: a lagged
    damper adds stiffness, saturated Bouc-Wen hysteresis looks like friction (and like stiffness at small
    amplitude), a bump stop like stiffening (each effect says which shapes resemble it)."""
    out: dict[str, list[tuple[str, float]]] = {s.name: [] for v in all_shapes().values() for s in v}
    for shape, pairs in PARAMETER_AFFINITY.items():
        out[shape].extend(pairs)
    for e in LIBRARY.values():
        for shape, affinity in e.resembles.items():
            out.setdefault(shape, []).append((e.name, affinity))
    return {k: tuple(v) for k, v in out.items()}


def __getattr__(name: str):
    """SHAPES (variable -> shape names) and SHAPE_EFFECTS follow the registry."""
    if name == "SHAPES":
        return {v: tuple(s.name for s in shapes) for v, shapes in all_shapes().items()}
    if name == "SHAPE_EFFECTS":
        return shape_effects()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


# ------------------------------------------------------------------------------------------ results


@dataclass(frozen=True)
class Resemblance(Result):
    """How well each library shape, scaled by one least-squares amplitude, matches an estimated curve."""

    best: str
    r2: dict[str, float]  # uncentred weighted R² per shape (0 when the amplitude must have the other sign)
    amplitude: dict[str, float]  # fitted amplitude per shape [N per unit of the shape]
    detail: dict[str, str]  # how a profiled shape was chosen (dead band width, one-sided direction)


class EstimatedCurve(Protocol):
    """What points_to reads of one estimated curve (unexplained.Curve)."""

    chi2_explained: float
    resembles: Resemblance

    @property
    def significant(self) -> bool: ...


class AxleCurves(Protocol):
    """What points_to reads of one axle's estimate (unexplained.AxleEstimate)."""

    axle: str
    g: EstimatedCurve
    h: EstimatedCurve


class Estimate(Protocol):
    """What points_to reads of the non-parametric estimate (unexplained.Unexplained, whose module compares
    its curves with the shapes here and so imports this one)."""

    p_value: float
    front: AxleCurves
    rear: AxleCurves


# ------------------------------------------------------------------------------------------ shapes


def _shape_columns(variable: str, x: NDArray) -> dict[str, list[tuple[NDArray, int, str]]]:
    """Each shape's candidate curves over x: (curve, sign constraint of the amplitude (0: free), detail)."""
    return {s.name: s.curves(x) for s in all_shapes()[variable]}


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


def points_to(unexplained: Estimate, alpha: float = ALPHA) -> tuple[str, ...]:
    """The library effects and known parameters (``parameter:kf``-style) the significant estimated curves resemble,
    best first by R² x the affinity of the shape to the candidate, weighted by the residual power each curve
    explains (ties in the order first met), those within POINT_SHARE of the best; none when the estimate is not
    significant (p >= alpha)."""
    if not unexplained.p_value < alpha:
        return ()
    score: dict[str, float] = {}
    pointers = shape_effects()
    total = sum(c.chi2_explained for a in (unexplained.front, unexplained.rear) for c in (a.g, a.h)) or 1.0
    for a in (unexplained.front, unexplained.rear):
        tag = a.axle[0]
        for c in (a.g, a.h):
            if not c.significant:
                continue
            weight = c.chi2_explained / total
            for shape, r2 in c.resembles.r2.items():
                for effect, affinity in pointers.get(shape, ()):
                    effect = effect.format(axle=tag)
                    score[effect] = max(score.get(effect, 0.0), weight * max(r2, 0.0) * affinity)
    top = max(score.values(), default=0.0)
    if not top > 0.0:
        return ()
    return tuple(e for e in sorted(score, key=lambda e: -score[e]) if score[e] >= POINT_SHARE * top)
