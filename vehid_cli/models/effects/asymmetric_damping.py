"""Asymmetric damping: rebound and compression damping c + dc/2 and c - dc/2 (c the configured linear damping of the
axle), blended by the smooth switch of Fleps-Dezasse Eq. 4-5, s = (1 + tanh(v / v_eps)) / 2: adds
f = dc (s - 1/2) v [N]."""

from __future__ import annotations

import math

import numpy as np

from .base import SLOT, BenchScale, CandidateForm, CarScale, Effect, Param, Shape, per_axle_candidate, velocity_starts

ASYM_EPS = 0.02  # [m/s] the library's switch width: the shape the non-parametric estimate compares with


def force(x, v, c, i, p, z, zd, f, damper):
    """Its force on strut i (the contract: models/effects/base.py)."""
    if p[SLOT.on] != 0.0:
        f += 0.5 * p[SLOT.dc + i] * math.tanh(v / p[SLOT.v_eps]) * v
    return f, damper


def car(s: CarScale) -> CandidateForm:
    """dc per axle within +-2 c; the re-fit also frees the damping it splits (cf, cr)."""
    return per_axle_candidate(
        "asymmetric_damping", "dc", lambda c: -2 * c, lambda c: 2 * c, s, companions=("cf", "cr"),
        shape_limits={"asymmetric_damping.v_eps": (1e-3, 0.5)}, starts=velocity_starts("asymmetric_damping.v_eps"),
    )  # fmt: skip


def bench(s: BenchScale) -> CandidateForm:
    """dc within +-10 F / V; the switch width from the velocity scales."""
    return CandidateForm(
        ("asymmetric_damping.dc",), {"asymmetric_damping.dc": (-10 * s.F / s.V, 10 * s.F / s.V)},
        {"asymmetric_damping.dc": 0.0, "asymmetric_damping.v_eps": 0.2 * s.V}, ("asymmetric_damping.v_eps",),
        {"asymmetric_damping.v_eps": (0.005 * s.V, 2 * s.V)}, strength=("asymmetric_damping.dc",),
        null={"asymmetric_damping.dc": 0.0}, starts=tuple({"asymmetric_damping.v_eps": v} for v in s.velocities),
    )  # fmt: skip


EFFECT = Effect(
    "asymmetric_damping",
    "rebound/compression damping c + dc/2 / c - dc/2 with the smooth switch of Fleps-Dezasse Eq. 4-5",
    (
        Param("dc", 0.0, -1e5, 1e5, "N s/m", "rebound minus compression damping (|dc| < 2 c)"),
        Param("v_eps", 0.02, 0.0, 10.0, "m/s", "width of the smooth switch", per_axle=False, open_lower=True),
    ),
    strength="dc",
    force=force,
    order=10,
    bench=True,
    car_candidate=car,
    bench_candidate=bench,
    shapes=(
        Shape(
            "asymmetric_damping",
            "velocity",
            lambda x: [(x * np.tanh(x / ASYM_EPS), 0, f"v tanh(v / {ASYM_EPS}) (the library's)")],
            rank=2,
        ),
    ),  # fmt: skip
    resembles={"asymmetric_damping": 1.0, "one_sided_damping": 1.0, "quadratic_damping": 0.6},
)
