"""Strut friction: f = Fc tanh(v / v_eps) [N], a smoothed Coulomb force."""

from __future__ import annotations

import math

import numpy as np

from .base import (
    SLOT,
    BenchScale,
    CandidateForm,
    CarScale,
    Effect,
    Param,
    Shape,
    constant,
    per_axle_candidate,
    velocity_starts,
)

COULOMB_EPS = 0.01  # [m/s] the library's smoothing: the shape the non-parametric estimate compares with


def force(x, v, c, i, p, z, zd, f, damper):
    """Its force on strut i (the contract: models/effects/base.py)."""
    if p[SLOT.on] != 0.0:
        f += p[SLOT.Fc + i] * math.tanh(v / p[SLOT.v_eps])
    return f, damper


def car(s: CarScale) -> CandidateForm:
    """Fc per axle up to 2 kN."""
    return per_axle_candidate(
        "coulomb_friction", "Fc", constant(0.0), constant(2000.0), s,
        shape_limits={"coulomb_friction.v_eps": (1e-3, 0.5)}, starts=velocity_starts("coulomb_friction.v_eps"),
    )  # fmt: skip


def bench(s: BenchScale) -> CandidateForm:
    """Fc up to 3 F; the smoothing from the velocity scales."""
    return CandidateForm(
        ("coulomb_friction.Fc",), {"coulomb_friction.Fc": (0.0, 3 * s.F)},
        {"coulomb_friction.Fc": 0.0, "coulomb_friction.v_eps": 0.1 * s.V}, ("coulomb_friction.v_eps",),
        {"coulomb_friction.v_eps": (0.005 * s.V, 2 * s.V)}, strength=("coulomb_friction.Fc",),
        null={"coulomb_friction.Fc": 0.0}, starts=tuple({"coulomb_friction.v_eps": v} for v in s.velocities),
    )  # fmt: skip


EFFECT = Effect(
    "coulomb_friction",
    "strut friction Fc tanh(v / v_eps)",
    (
        Param("Fc", 0.0, 0.0, 1e4, "N", "friction force level"),
        Param("v_eps", 0.01, 0.0, 10.0, "m/s", "tanh smoothing velocity", per_axle=False, open_lower=True),
    ),
    strength="Fc",
    force=force,
    order=20,
    bench=True,
    car_candidate=car,
    bench_candidate=bench,
    shapes=(
        Shape(
            "coulomb_friction",
            "velocity",
            lambda x: [(np.tanh(x / COULOMB_EPS), 1, f"v_eps = {COULOMB_EPS} m/s")],
            rank=1,
        ),
    ),  # fmt: skip
    resembles={"coulomb_friction": 1.0, "sqrt_damper": 0.7},
)
