"""A gas spring's nonlinear part: a polytropic charge of preload F0 [N] and gas column L [m], compressed by -d:
f = F0 (1 - (1 + d/L)^-kappa) - F0 kappa d / L. Its linear part F0 kappa / L belongs to the configured spring
(kf, kr); what remains stiffens in compression and softens in rebound. On a bench the damper's own gas force
k1 (x - x0) plays this part (its candidate frees k1 and x0)."""

from __future__ import annotations

import numpy as np

from .base import SLOT, BenchScale, CandidateForm, CarScale, Effect, Param, Shape, constant, per_axle_candidate

GAS_L, GAS_KAPPA = 0.1, 1.4  # the library's defaults [m], [-]: the shape the non-parametric estimate compares with


def force(x, v, c, i, p, z, zd, f, damper):
    """Its force on strut i (the contract: models/effects/base.py)."""
    if p[SLOT.on] != 0.0:
        F0, L, kap = p[SLOT.F0 + i], p[SLOT.L], p[SLOT.kappa]
        if F0 != 0.0:
            f += F0 * (1.0 - (1.0 + x / L) ** (-kap)) - F0 * kap * x / L
    return f, damper


def car(s: CarScale) -> CandidateForm:
    """F0 per axle up to 20 kN; the gas column from 2 cm to 1 m."""
    return per_axle_candidate(
        "gas_spring", "F0", constant(0.0), constant(2e4), s, shape_limits={"gas_spring.L": (0.02, 1.0)},
        starts=tuple({"gas_spring.L": s} for s in (0.04, 0.1, 0.3)),
    )  # fmt: skip


def bench(s: BenchScale) -> CandidateForm:
    """The damper's own gas force k1 (x - x0): k1 up to 20 F / X, x0 from the stroke's mean."""
    return CandidateForm(
        ("k1", "x0"), {"k1": (0.0, 20 * s.F / s.X), "x0": (-1.0, 1.0)}, {"k1": 0.1 * s.F / s.X, "x0": s.x_mean},
        strength=("k1",), null={"k1": 0.0}, linear=False,
    )  # fmt: skip


def _curve(x):
    u = np.maximum(x / GAS_L, -0.9)
    return [((1.0 - (1.0 + u) ** (-GAS_KAPPA)) - GAS_KAPPA * u, 1, f"L = {GAS_L} m, kappa = {GAS_KAPPA}")]


EFFECT = Effect(
    "gas_spring",
    "nonlinear part of a polytropic gas charge: preload F0, gas column L, exponent kappa",
    (
        Param("F0", 0.0, 0.0, 1e6, "N", "gas preload at static equilibrium"),
        Param("L", 0.1, 0.0, 10.0, "m", "equivalent gas column length", per_axle=False, open_lower=True),
        Param("kappa", 1.4, 1.0, 2.0, "-", "polytropic exponent", per_axle=False),
    ),
    strength="F0",
    force=force,
    order=50,
    car_candidate=car,
    bench_candidate=bench,
    shapes=(Shape("gas_spring", "deflection", _curve, rank=2),),
    resembles={"gas_spring": 1.0, "progressive_spring": 0.5},
)
