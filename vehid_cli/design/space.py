"""The design space: the variables the `design:` section gives a range (`Space`), how a vector of them makes a plan
from a base plan, and the grids along one variable that the search, the profiles and the proposals walk.

Heights are designed as ratios: the responses are linear in the road, so the highest corner sits at
`design.heights.max` and the variables are `side` s in [-(1 - min/max), 1 - min/max] (s >= 0: side b1 at max, side
b2 at (1 - s) max; s < 0 the other way round) and, with `per_axle`, `axle` (rear against front, the same way).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..config.design import Design
from .plan import Plan, axle_of, corner_heights, side_of

VARIABLES = ("speed_kmh", "side", "axle", "length", "duration", "shape")
LABELS = {
    "speed_kmh": "speed",
    "side": "left/right heights",
    "axle": "front/rear heights",
    "length": "bump length",
    "duration": "duration",
    "shape": "bump shape",
}


@dataclass(frozen=True)
class Space:
    """The designed variables (VARIABLES with a range) and how a vector of them makes a plan from a base plan."""

    free: tuple[str, ...]
    lower: NDArray
    upper: NDArray
    shapes: tuple[str, ...]
    top: float | None  # the highest corner's height [m] (None: heights not designed)
    low: float  # no corner below this [m]

    def plan(self, x: NDArray, base: Plan) -> Plan:
        """The base plan with the free variables set to x (the shape variable is an index into `shapes`)."""
        v = dict(zip(self.free, np.asarray(x, dtype=float), strict=True))
        heights = base.heights
        if "side" in v or "axle" in v:
            top = self.top if self.top is not None else max(base.heights)
            side, axle = v.get("side", side_of(base.heights)), v.get("axle", axle_of(base.heights))
            heights = corner_heights(top, side, axle, self.low)
        shape = self.shapes[int(round(v["shape"]))] if "shape" in v else base.shape
        return dataclasses.replace(
            base, speed_kmh=float(v.get("speed_kmh", base.speed_kmh)), heights=heights, shape=shape,
            length=float(v.get("length", base.length)), duration=float(v.get("duration", base.duration)),
        )  # fmt: skip

    def vector(self, plan: Plan) -> NDArray:
        """The free variables of a plan."""
        known = {
            "speed_kmh": plan.speed_kmh, "side": side_of(plan.heights), "axle": axle_of(plan.heights),
            "length": plan.length, "duration": plan.duration,
            "shape": self.shapes.index(plan.shape) if plan.shape in self.shapes else 0,
        }  # fmt: skip
        return np.array([known[n] for n in self.free])


def design_space(design: Design) -> Space:
    """The variables the design section gives ranges to."""
    free, lower, upper = [], [], []

    def add(name: str, lo: float, hi: float) -> None:
        free.append(name)
        lower.append(lo)
        upper.append(hi)

    if design.speed_kmh is not None:
        add("speed_kmh", *design.speed_kmh)
    top, low = None, 0.0
    if design.heights is not None:
        top, low = design.heights.max, design.heights.min
        span = 1.0 - low / top
        add("side", -span, span)
        if design.heights.per_axle:
            add("axle", -span, span)
    if design.length is not None:
        add("length", *design.length)
    if design.duration is not None:
        add("duration", *design.duration)
    shapes = tuple(design.shapes or ())
    if len(shapes) > 1:
        add("shape", 0, len(shapes) - 1)
    return Space(tuple(free), np.array(lower, float), np.array(upper, float), shapes, top, low)


def variable_grid(space: Space, name: str, points: int) -> NDArray:
    """`points` values of a variable over its range (every shape's index for `shape`)."""
    i = space.free.index(name)
    if name == "shape":
        return np.arange(len(space.shapes), dtype=float)
    return np.linspace(space.lower[i], space.upper[i], points)


def line_through(space: Space, x: NDArray, name: str, points: int) -> tuple[NDArray, NDArray]:
    """The grid of one variable and the vectors (one per grid value) equal to x in every other variable."""
    grid = variable_grid(space, name, points)
    X = np.repeat(x[None, :], grid.size, axis=0)
    X[:, space.free.index(name)] = grid
    return grid, X


def natural(space: Space, name: str, x: NDArray) -> NDArray:
    """A variable in natural units: `side`/`axle` as the lower height over the higher one."""
    x = np.asarray(x, dtype=float)
    return 1.0 - np.abs(x) if name in ("side", "axle") else x
