"""The half car as a system: q = [x, theta, x1, x2] (bounce up +, pitch nose down +, front and rear wheel up +,
from static equilibrium), inputs [road1 (front), road2 (rear)]. The body point at xp forward of the CG moves
x - xp theta (SPEC section 1: z1 = x - a1 theta above the front axle, x + a2 theta above the rear).

    V = kf/2 (x - a1 theta - x1)² + kr/2 (x + a2 theta - x2)² + ktf/2 (x1 - y1)² + ktr/2 (x2 - y2)²
    D = cf/2 (x' - a1 theta' - x1')² + cr/2 (x' + a2 theta' - x2')²,   T = (m x'² + Iy theta'² + mf x1'² + mr x2'²)/2

The wheelbase stays fixed when a1 moves (a2 = wheelbase - a1). From the road alone, scaling every mass, inertia,
stiffness and damping by one factor leaves every channel unchanged.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from ...config.lumped import LumpedConfig
from ..lumped import LumpedSystem, road_profile

SCALES = ("m", "Iy", "mf", "mr", "kf", "kr", "ktf", "ktr", "cf", "cr")


def _body_x(origin: str | None, x: float | None, a1: NDArray, a2: NDArray) -> NDArray:
    """Forward distance (P,) of a body point from the CG: an axle-referenced sensor stays put as the CG moves."""
    base = {"cg": np.zeros_like(a1), "front_axle": a1, "rear_axle": -a2}[origin or "cg"]
    return base + (x or 0.0)


class HalfCarSystem(LumpedSystem):
    name: ClassVar[str] = "half_car"
    groups: ClassVar[tuple[tuple[str, tuple[str, ...]], ...]] = (
        ("springs", ("kf", "kr")), ("dampers", ("cf", "cr")), ("tyres", ("ktf", "ktr")),
        ("unsprung masses", ("mf", "mr")), ("body", ("m", "Iy", "a1")),
    )  # fmt: skip

    def matrices(self, p: dict[str, NDArray]) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray]:
        v = {n: np.asarray(p[n], dtype=float) for n in p}
        P = v["m"].shape[0]
        a1, a2 = v["a1"], v["wheelbase"] - v["a1"]
        # suspension deflections d = D q (front, rear), tyres x_i - y_i = E q - y
        D = np.zeros((P, 2, 4))
        D[:, 0, 0], D[:, 0, 1], D[:, 0, 2] = 1.0, -a1, -1.0
        D[:, 1, 0], D[:, 1, 1], D[:, 1, 3] = 1.0, a2, -1.0
        E = np.zeros((2, 4))
        E[0, 2] = E[1, 3] = 1.0
        ks = np.stack([v["kf"], v["kr"]], -1)
        cs = np.stack([v["cf"], v["cr"]], -1)
        kt = np.stack([v["ktf"], v["ktr"]], -1)
        Dt = np.swapaxes(D, -1, -2)
        K = Dt @ (ks[..., None] * D) + E.T @ (kt[..., None] * E)
        C = Dt @ (cs[..., None] * D)
        M = np.zeros((P, 4, 4))
        for i, n in enumerate(("m", "Iy", "mf", "mr")):
            M[:, i, i] = v[n]
        B0 = E.T * kt[:, None, :]
        return M, C, K, B0, np.zeros_like(B0)

    def struts(self, p: dict[str, NDArray]) -> tuple[NDArray, NDArray, NDArray, NDArray | None]:
        a1 = np.asarray(p["a1"], dtype=float)
        a2 = np.asarray(p["wheelbase"], dtype=float) - a1
        P = a1.shape[0]
        D, T, ET = np.zeros((P, 4, 4)), np.zeros((P, 4, 4)), np.zeros((4, 2))
        D[:, 0, 0], D[:, 0, 1], D[:, 0, 2] = 1.0, -a1, -1.0  # front: the body above the axle minus the wheel
        D[:, 2, 0], D[:, 2, 1], D[:, 2, 3] = 1.0, a2, -1.0  # rear (corner slot 2: the rear axle)
        T[:, 0, 2], T[:, 2, 3] = 1.0, 1.0
        ET[0, 0], ET[2, 1] = -1.0, -1.0
        return D, T, ET, None

    def strut_damping(self, p: dict[str, NDArray]) -> NDArray:
        return np.stack([p["cf"], p["cr"]], axis=-1)

    def sensor_rows(self, p: dict[str, NDArray]) -> tuple[NDArray, NDArray]:
        a1 = np.asarray(p["a1"], dtype=float)
        a2 = np.asarray(p["wheelbase"], dtype=float) - a1
        P = a1.shape[0]
        rows = {"disp": [], "acc": []}
        for s in self.config.layout:
            r = np.zeros((P, 4))
            if s.kind.startswith("body"):
                r[:, 0], r[:, 1] = 1.0, -_body_x(s.origin, s.x, a1, a2)
            elif s.kind.startswith("wheel"):
                r[:, 1 + s.corner] = 1.0
            else:  # deflection: the body above the axle minus the wheel
                r[:, 0], r[:, 1], r[:, 1 + s.corner] = 1.0, (-a1 if s.corner == 1 else a2), -1.0
            rows[s.family].append(r)
        out = [np.stack(rows[f], axis=1) if rows[f] else np.zeros((P, 0, 4)) for f in ("disp", "acc")]
        return out[0], out[1]

    @classmethod
    def configured_inputs(cls, config: LumpedConfig, t: NDArray) -> NDArray:
        return np.column_stack([road_profile(config, t, d) for d in config.delays()])

    def remedies(self, free: tuple[str, ...]) -> str:
        known = [n for n in SCALES if n in free]
        fixes = []
        if known:
            fixes.append(f"fix one of {', '.join(known)} at its known value (remove it from identify.unknowns): a "
                         "weighed mass or a measured spring rate sets the scale; no sensor can, the road moves the car "
                         "the same way at every scale")  # fmt: skip
        fixes.append("or add a sensor that sees what is free (a body sensor away from the CG for the pitch, a "
                     "deflection or wheel sensor for a wheel)")  # fmt: skip
        return "; ".join(fixes)
