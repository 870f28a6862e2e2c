"""Backlash: play of width gap between strut and damper. The damper piston x_b (one state per strut, centred at rest)
is driven through contact faces of stiffness k_contact that close after a dead zone of gap/2 either way: the
transmitted force F = k_contact deadzone(d - x_b) [N], xd_b = F / c. It replaces the configured damper force c v;
gap = 0 is the rigid mount. On a bench the damper's own play `gap` plays this part."""

from __future__ import annotations

import numpy as np

from .base import SLOT, BenchScale, CandidateForm, CarScale, Effect, Param, Shape, constant, per_axle_candidate

STABLE = 0.9  # of the stiffest contact RK4 can step: the candidate's upper bound (its state still decays)


def force(x, v, c, i, p, z, zd, f, damper):
    """Its force on strut i (the contract: models/effects/base.py)."""
    if p[SLOT.on] != 0.0:
        j = int(p[SLOT.z]) + i
        half = 0.5 * p[SLOT.gap + i]
        if half > 0.0:
            r = x - z[j]
            pen = r - half if r > half else (r + half if r < -half else 0.0)
            damper = p[SLOT.k_contact] * pen
            zd[j] = damper / c
        else:
            zd[j] = 0.0
    return f, damper


def car(s: CarScale) -> CandidateForm:
    """gap per axle from 10 um to 2 cm; the contact stiffness from 1e4 N/m up to 1e8 N/m or, on RK4, below that STABLE
    of the stiffest its step can take (`stiffest_contact`): a stiffer contact diverges at the run's step. Data without
    play pull the fit to the rigid mount (the gap at its floor, the contact at its stiffest), where it crept along
    the edge of divergence for ~100 simulations: that corner is one more start."""
    k_max = 1e8 if s.h is None else max(1e5, min(1e8, STABLE * stiffest_contact(min(s.cf, s.cr), s.h)))
    gaps = tuple({"backlash.gap_f": g, "backlash.gap_r": g} for g in (1e-4, 1e-3, 5e-3))
    rigid = {"backlash.gap_f": 1e-5, "backlash.gap_r": 1e-5, "backlash.k_contact": k_max}
    return per_axle_candidate(
        "backlash", "gap", constant(1e-5), constant(0.02), s, start=1e-4,
        shape_limits={"backlash.k_contact": (1e4, k_max)}, linear=False, starts=(*gaps, rigid),
    )  # fmt: skip


def stiffest_contact(c: float, h: float) -> float:
    """The contact stiffness [N/m] at which RK4 of step h [s] stops damping the piston's state (xd_b = k (d - x_b) / c
    in contact: eigenvalue -k / c [1/s]): the end of RK4's real stability interval (the real root of
    1 + z/2 + z^2/6 + z^3/24 = 0, z = -2.785) times c / h."""
    roots = np.roots([1 / 24, 1 / 6, 1 / 2, 1.0])
    return float(-roots[np.abs(roots.imag) < 1e-12].real.min()) * c / h


def bench(s: BenchScale) -> CandidateForm:
    """The damper's own play `gap`, up to half the stroke's spread."""
    return CandidateForm(
        ("gap",), {"gap": (0.0, 0.5 * s.X)}, {"gap": 0.01 * s.X}, strength=("gap",), null={"gap": 0.0}, linear=False,
        starts=tuple({"gap": g * s.X} for g in (0.003, 0.01, 0.05)),
    )  # fmt: skip


def _dead_bands(x):
    xm = max(float(np.max(np.abs(x))), 1e-300)
    return [
        (np.sign(x) * np.maximum(np.abs(x) - f * xm, 0.0), 1, f"dead band +-{f * xm:.4g} m") for f in (0.2, 0.4, 0.6)
    ]


EFFECT = Effect(
    "backlash",
    "play of width gap before the damper engages, contact faces of stiffness k_contact",
    (
        Param("gap", 0.0, 0.0, 0.1, "m", "total play (dead zone gap/2 either way)"),
        Param("k_contact", 2e6, 0.0, 1e10, "N/m", "contact stiffness", per_axle=False, open_lower=True),
    ),
    strength="gap",
    force=force,
    order=70,
    states=1,
    car_candidate=car,
    bench_candidate=bench,
    shapes=(Shape("dead_band", "deflection", _dead_bands, rank=3),),
    resembles={"dead_band": 1.0, "progressive_spring": 0.3},
)
