"""Where the sensors are: the car's output equation for any layout of body, wheel and deflection sensors.

A channel is linear in the car's motion: a body sensor at (x, y) sees the body point
z = x_b + y phi - x theta (x forward and y toward side 1, the side of corners 1 and 4, from the CG: Gökdağ
Eq. 7 is the case of the four points above the corners), a wheel sensor sees the wheel hop x_i, a deflection
sensor the suspension deflection z_i - x_i (body point above corner i minus the wheel; up = extension).
Each measures acceleration or displacement. A body sensor's position may be given from a named reference
point (a corner, an axle centre) instead of the CG: when the CG is among the unknowns (a1, b1), the sensor
stays where it was mounted and the CG moves under it.

Channels come in two families for noise and objectives: `acc` (m/s²: body_acc, wheel_acc) and `disp`
(m: body_disp, wheel_disp, deflection). The default layout is the paper's: acc1..acc4 and disp1..disp4 at the
body points above the corners.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cached_property
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

SensorKind = Literal["body_acc", "body_disp", "wheel_acc", "wheel_disp", "deflection"]
SENSOR_KINDS: tuple[str, ...] = ("body_acc", "body_disp", "wheel_acc", "wheel_disp", "deflection")
FAMILY = {"body_acc": "acc", "wheel_acc": "acc", "body_disp": "disp", "wheel_disp": "disp", "deflection": "disp"}
FAMILIES = ("acc", "disp")  # the order channels are grouped in (noise draws, residuals)
UNIT = {"acc": "m/s^2", "disp": "m"}
REFERENCE_POINTS = ("cg", "corner1", "corner2", "corner3", "corner4", "front_axle", "rear_axle")


@dataclass(frozen=True)
class Sensor:
    """One channel: its name, what it measures, and where (x, y [m] from `origin` for body sensors; the corner
    1..4 for wheel and deflection sensors)."""

    name: str
    kind: str  # one of SENSOR_KINDS
    x: float = 0.0  # [m] forward of the origin (body sensors)
    y: float = 0.0  # [m] toward side 1 from the origin (body sensors)
    origin: str = "cg"  # one of REFERENCE_POINTS (body sensors)
    corner: int = 0  # 1..4 (wheel and deflection sensors)

    @property
    def family(self) -> str:
        return FAMILY[self.kind]

    @property
    def point(self) -> tuple[str, float, float] | None:
        """The body point this channel reads (origin, x, y), or None for a wheel sensor."""
        if self.kind.startswith("body"):
            return (self.origin, self.x, self.y)
        if self.kind == "deflection":
            return (f"corner{self.corner}", 0.0, 0.0)
        return None


def _origin(name: str, p: Mapping[str, ArrayLike]) -> tuple[NDArray, NDArray]:
    """(x, y) [m] of a reference point from the CG, for a batch of cars (a1, a2, b1, b2 arrays)."""
    return _origins(p)[name]


def _origins(p: Mapping[str, ArrayLike]) -> dict[str, tuple[NDArray, NDArray]]:
    """(x, y) [m] of every reference point from the CG, for a batch of cars (a1, a2, b1, b2 arrays)."""
    a1, a2, b1, b2 = np.broadcast_arrays(*(np.asarray(p[k], dtype=float) for k in ("a1", "a2", "b1", "b2")))
    zero = np.zeros_like(a1)
    return {
        "cg": (zero, zero),
        "corner1": (a1, b1),
        "corner2": (a1, -b2),
        "corner3": (-a2, -b2),
        "corner4": (-a2, b1),
        "front_axle": (a1, (b1 - b2) / 2),
        "rear_axle": (-a2, (b1 - b2) / 2),
    }


@dataclass(frozen=True)
class Layout:
    """The sensors of a test, in declaration order; channels are read grouped by family (acc, then disp)."""

    sensors: tuple[Sensor, ...]

    def __post_init__(self) -> None:
        names = [s.name for s in self.sensors]
        if len(set(names)) != len(names):
            raise ValueError(f"sensor names repeat: {sorted({n for n in names if names.count(n) > 1})}")

    @property
    def families(self) -> tuple[str, ...]:
        """The families present, in FAMILIES order."""
        return tuple(f for f in FAMILIES if any(s.family == f for s in self.sensors))

    def of(self, family: str) -> tuple[Sensor, ...]:
        return tuple(s for s in self.sensors if s.family == family)

    def names(self, family: str) -> tuple[str, ...]:
        """Channel names of a family, in declaration order."""
        return tuple(s.name for s in self.of(family))

    @property
    def channel_names(self) -> tuple[str, ...]:
        """Every channel, grouped by family."""
        return tuple(n for f in self.families for n in self.names(f))

    @cached_property
    def _points(self) -> tuple[tuple[str, float, float], ...]:
        """The distinct body points read, in first-use order."""
        seen: dict[tuple[str, float, float], None] = {}
        for s in self.sensors:
            if s.point is not None:
                seen.setdefault(s.point)
        return tuple(seen)

    def points(self, p: Mapping[str, ArrayLike]) -> NDArray:
        """Rows (..., nb, 3) mapping [x_b, phi, theta] to the vertical motion of each body point, for a batch of
        cars (parameter arrays of one batch shape): [1, y, -x] with (x, y) from the CG."""
        if not self._points:
            a1 = np.asarray(p["a1"], dtype=float)
            return np.zeros(a1.shape + (0, 3))
        origins = _origins(p)  # once for every point: the simulation asks for them on every batch
        rows = np.empty(origins["cg"][0].shape + (len(self._points), 3))
        rows[..., 0] = 1.0
        for i, (origin, dx, dy) in enumerate(self._points):
            ox, oy = origins[origin]
            rows[..., i, 1] = oy + dy
            rows[..., i, 2] = -(ox + dx)
        return rows

    def body_xy(self, p: Mapping[str, float]) -> dict[str, tuple[float, float]]:
        """(x, y) [m] from the CG of each body sensor's point (x forward, y toward side 1), for one car."""
        out = {}
        for s in self.sensors:
            if s.kind.startswith("body"):
                ox, oy = _origin(s.origin, p)
                out[s.name] = (float(ox) + s.x, float(oy) + s.y)
        return out

    @cached_property
    def column_groups(self) -> tuple[tuple[tuple[str, int], ...], ...]:
        """The response columns (field, index) the channels are read from: one group per family in `families` order
        (channel j of the family from its column j; a deflection from its body point's disp), then one group of the
        wheel hops the deflections subtract (empty without deflections). A simulator that computes only these
        (sim.linear.simulate_columns) skips the rest of the response; `read_columns` makes the channels."""
        index = {pt: i for i, pt in enumerate(self._points)}
        source = {"body_acc": "acc", "body_disp": "disp", "deflection": "disp", "wheel_acc": "qdd", "wheel_disp": "q"}
        groups, wheels = [], []
        for family in self.families:
            group = []
            for s in self.of(family):
                at = index[s.point] if s.point is not None else 2 + s.corner
                group.append((source[s.kind], at))
                if s.kind == "deflection":
                    wheels.append(("q", 2 + s.corner))
            groups.append(tuple(group))
        return (*groups, tuple(wheels))

    def read_columns(self, columns: Sequence[NDArray]) -> dict[str, NDArray]:
        """Family -> (..., n, k) from arrays (..., n, len(group)) holding `column_groups`' columns, the same numbers
        as `read` (the arrays are used in place: a deflection's wheel hop is subtracted from its column)."""
        *families, wheels = columns
        out = dict(zip(self.families, families, strict=True))
        j = 0
        for family, values in out.items():
            for col, s in enumerate(self.of(family)):
                if s.kind == "deflection":
                    values[..., col] -= wheels[..., j]
                    j += 1
        return out

    def read(self, response) -> dict[str, NDArray]:
        """Family -> (..., n, k) channel values of a response simulated at `points` (sim.linear.Response)."""
        index = {pt: i for i, pt in enumerate(self._points)}
        out = {}
        for family in self.families:
            cols = []
            for s in self.of(family):
                if s.kind == "body_acc":
                    cols.append(response.acc[..., index[s.point]])
                elif s.kind == "body_disp":
                    cols.append(response.disp[..., index[s.point]])
                elif s.kind == "wheel_acc":
                    cols.append(response.qdd[..., 2 + s.corner])
                elif s.kind == "wheel_disp":
                    cols.append(response.q[..., 2 + s.corner])
                else:  # deflection: body point above the corner minus the wheel
                    cols.append(response.disp[..., index[s.point]] - response.q[..., 2 + s.corner])
            out[family] = np.stack(cols, axis=-1)
        return out


def corner_layout() -> Layout:
    """The paper's layout: accelerometers acc1..acc4 and displacement sensors disp1..disp4 at the body points above
    the corners (SPEC section 1)."""
    acc = [Sensor(f"acc{i}", "body_acc", origin=f"corner{i}") for i in range(1, 5)]
    disp = [Sensor(f"disp{i}", "body_disp", origin=f"corner{i}") for i in range(1, 5)]
    return Layout(tuple(acc + disp))
