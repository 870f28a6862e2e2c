"""Profiles: the criterion along one design variable (speed, the side ratio), the others held at a plan: the curves
of the figures, through the designed test and through the configured one.

(Not a campaign sweep of `vehid sweep`: a profile varies one variable of the test and scores each point by its
bound; nothing is identified.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .plan import Plan
from .scoring import Scorer
from .space import Space, line_through, natural


@dataclass(frozen=True)
class Profile:
    """The criterion and the NRE bound along one variable, the others held at a plan; `values` in the variable's
    natural units (km/h, m, s; `side`: the lower side's height over the higher side's)."""

    variable: str
    through: str  # "designed" or "configured"
    x: NDArray  # the variable (the design vector's units)
    values: NDArray  # natural units, for the figure's axis
    criterion: NDArray
    nre: NDArray


def profiles_through(scorer: Scorer, space: Space, plans: dict[str, Plan], points: int) -> list[Profile]:
    """The criterion along speed and along the side ratio through each plan (figures); the side profile keeps the
    higher side of the plan (ratio = lower over higher)."""
    out = []
    for name in ("speed_kmh", "side"):
        if name not in space.free:
            continue
        for through, plan in plans.items():
            x = space.vector(plan)
            grid, X = line_through(space, x, name, points)
            if name == "side":  # one branch: the plan's higher side stays the higher
                sign = 1.0 if x[space.free.index("side")] >= 0 else -1.0
                grid = sign * np.linspace(0.0, space.upper[space.free.index("side")], points)
                X[:, space.free.index("side")] = grid
            scores = scorer(space, plan, X)
            out.append(Profile(name, through, grid, natural(space, name, grid),
                               np.array([s.criterion for s in scores]), np.array([s.nre for s in scores])))  # fmt: skip
    return out
