"""Proposals: when the configured test cannot identify every unknown, the cheapest single-variable changes of it
that can (smallest change as a fraction of the variable's range first), so the user can fix the test they have
before adopting the designed one."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..config import Config
from .criterion import Evaluation
from .scoring import Scorer
from .space import Space, line_through, natural


@dataclass(frozen=True)
class Proposal:
    """A single-variable change of the configured test that makes every unknown identifiable."""

    variable: str
    value: float  # the new value (natural units: km/h, ratio, m, s; a shape's index into design.shapes)
    text: str  # e.g. "unequal left/right heights: ratio 0.9"
    change: float  # the change as a fraction of the variable's range (the cheapest is the smallest)
    nre_rms_percent: float  # the NRE bound of the changed test
    identifies: tuple[str, ...]  # the unknowns it makes identifiable


def _describe(name: str, value: float, space: Space) -> str:
    if name == "speed_kmh":
        return f"speed {value:.3g} km/h"
    if name == "side":
        return f"unequal left/right heights: ratio {value:.2g}"
    if name == "axle":
        return f"unequal front/rear heights: ratio {value:.2g}"
    if name == "length":
        return f"bump length {value:.3g} m"
    if name == "duration":
        return f"duration {value:.3g} s"
    return f"bump shape {space.shapes[int(value)]}"


def cheapest_changes(
    scorer: Scorer, config: Config, space: Space, configured: Evaluation, points: int
) -> list[Proposal]:
    """Single-variable changes of the configured test (each variable over its grid, the others as configured; the
    heights keep the configured highest corner) that make every unknown identifiable, cheapest (smallest change as
    a fraction of the variable's range) first, one per variable."""
    lost = [n for n, ok in zip(configured.bound.names, configured.bound.identifiable, strict=True) if not ok]
    if not lost or not space.free:
        return []
    local = dataclasses.replace(space, top=max(configured.plan.heights))
    x0 = local.vector(configured.plan)
    out = []
    for name in local.free:
        i = local.free.index(name)
        grid, X = line_through(local, x0, name, 2 * points + 1)
        span = max(local.upper[i] - local.lower[i], 1e-300)
        changes = np.abs(grid - x0[i]) / span
        scores = scorer(local, configured.plan, X)
        ok = [k for k, s in enumerate(scores) if np.all(s.identifiable) and changes[k] > 0]
        if not ok:
            continue
        k = min(ok, key=lambda k: (changes[k], scores[k].nre))
        value = float(natural(local, name, grid[k])) if name != "shape" else float(grid[k])
        out.append(Proposal(name, value, _describe(name, value, local), float(changes[k]), scores[k].nre,
                            tuple(lost)))  # fmt: skip
    return sorted(out, key=lambda p: (p.change, p.nre_rms_percent))
