"""The quarter car as a system: q = [body, wheel] (up +, from static equilibrium), inputs [road1, force].

    ms zs'' = -ks (zs - zu) - cs (zs' - zu') + F
    mu zu'' =  ks (zs - zu) + cs (zs' - zu') - kt (zu - y) - ct (zu' - y') - F

The road y drives the wheel through the tyre spring and the tyre damper (ct sees the road's velocity, the slope of
the first-order hold); the actuator force F pushes the body up and the wheel down. From the road alone, scaling
all six parameters by one factor leaves every channel unchanged: a weighed mass or a measured force sets the scale.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from ...config.lumped import LumpedConfig
from ..lumped import LumpedSystem, force_profile, road_profile

ROWS = {"body_disp": (1.0, 0.0), "wheel_disp": (0.0, 1.0), "deflection": (1.0, -1.0)}
ACC_ROWS = {"body_acc": (1.0, 0.0), "wheel_acc": (0.0, 1.0)}
MASSES = ("ms", "mu")


class QuarterCarSystem(LumpedSystem):
    name: ClassVar[str] = "quarter_car"
    groups: ClassVar[tuple[tuple[str, tuple[str, ...]], ...]] = (
        ("dampers", ("cs", "ct")), ("springs", ("ks",)), ("tyres", ("kt",)), ("masses", ("mu", "ms")),
        ("actuator", ("force_gain",)),
    )  # fmt: skip
    axles: ClassVar[tuple[str, ...]] = ("f",)  # one strut: the effects' front-axle parameters
    companion_names: ClassVar[dict[str, str]] = {"cf": "cs", "kf": "ks", "ktf": "kt", "mf": "mu"}
    excluded_effects: ClassVar[tuple[str, ...]] = ("tyre_damping",)  # ct is the model's own: parameter:ct

    def struts(self, p: dict[str, NDArray]) -> tuple[NDArray, NDArray, NDArray, NDArray | None]:
        P = len(p["ms"])
        nu = len(self.config.input_names)
        D, T, ET = np.zeros((P, 4, 2)), np.zeros((P, 4, 2)), np.zeros((4, nu))
        D[:, 0] = (1.0, -1.0)  # body minus wheel
        T[:, 0] = (0.0, 1.0)  # wheel minus road
        ET[0, 0] = -1.0
        ct = np.zeros((P, 4))
        ct[:, 0] = p["ct"]
        return D, T, ET, ct

    def strut_damping(self, p: dict[str, NDArray]) -> NDArray:
        return np.stack([p["cs"], p["cs"]], axis=-1)

    def matrices(self, p: dict[str, NDArray]) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray]:
        ms, mu, ks, kt, cs, ct = (np.asarray(p[n], dtype=float) for n in ("ms", "mu", "ks", "kt", "cs", "ct"))
        P = ms.shape[0]
        zero = np.zeros(P)
        M = np.stack([np.stack([ms, zero], -1), np.stack([zero, mu], -1)], -2)
        C = np.stack([np.stack([cs, -cs], -1), np.stack([-cs, cs + ct], -1)], -2)
        K = np.stack([np.stack([ks, -ks], -1), np.stack([-ks, ks + kt], -1)], -2)
        B0 = np.zeros((P, 2, len(self.config.input_names)))
        B1 = np.zeros_like(B0)
        B0[:, 1, 0], B1[:, 1, 0] = kt, ct  # the road through the tyre spring and damper
        if B0.shape[-1] > 1:  # the actuator: body up, wheel down, by its gain
            gain = np.asarray(p["force_gain"], dtype=float)
            B0[:, 0, 1], B0[:, 1, 1] = gain, -gain
        return M, C, K, B0, B1

    def sensor_rows(self, p: dict[str, NDArray]) -> tuple[NDArray, NDArray]:
        P = len(next(iter(p.values())))
        layout = self.config.layout
        Sq = np.array([ROWS[s.kind] for s in layout if s.family == "disp"]).reshape(-1, 2)
        Sa = np.array([ACC_ROWS[s.kind] for s in layout if s.family == "acc"]).reshape(-1, 2)
        return np.broadcast_to(Sq, (P,) + Sq.shape).copy(), np.broadcast_to(Sa, (P,) + Sa.shape).copy()

    @classmethod
    def configured_inputs(cls, config: LumpedConfig, t: NDArray) -> NDArray:
        columns = [road_profile(config, t)]
        if config.road.actuator_force != "none":
            columns.append(force_profile(config, t))
        return np.column_stack(columns)

    def remedies(self, free: tuple[str, ...]) -> str:
        masses = [m for m in MASSES if m in free]
        fixes = []
        if masses:
            fixes.append(f"fix a mass at its weighed value (remove {' or '.join(masses)} from identify.unknowns)")
        if self.config.road.actuator_force == "none":
            fixes.append("add the actuator force (road: {input: measured, actuator_force: measured}, column force "
                         "[N]): a known force sets the scale")  # fmt: skip
        fixes.append("or add a sensor that sees what is free (no sensor fixes a common scale: every channel is "
                     "unchanged by it)")  # fmt: skip
        return "; ".join(fixes)
