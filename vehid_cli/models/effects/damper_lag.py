"""Damper lag: the damper force F_d follows its input (c v, or the backlash force) through a first-order lag of time
constant T (one state per strut): dF_d/dt = (c v - F_d) / T; adds F_d - c v [N]. T = 0 is no lag."""

from __future__ import annotations

from .base import SLOT, BenchScale, CandidateForm, CarScale, Effect, Param, constant, per_axle_candidate


def force(x, v, c, i, p, z, zd, f, damper):
    """Its force on strut i (the contract: models/effects/base.py)."""
    if p[SLOT.on] != 0.0:
        j = int(p[SLOT.z]) + i
        T = p[SLOT.T + i]
        if T > 0.0:
            zd[j] = (damper - z[j]) / T
            damper = z[j]
        else:
            zd[j] = 0.0
    return f, damper


def car(s: CarScale) -> CandidateForm:
    """T per axle from 1 to 100 ms."""
    return per_axle_candidate(
        "damper_lag", "T", constant(1e-3), constant(0.1), s, start=3e-3, linear=False,
        starts=tuple({"damper_lag.T_f": t, "damper_lag.T_r": t} for t in (2e-3, 8e-3, 3e-2)),
    )  # fmt: skip


def bench(s: BenchScale) -> CandidateForm:
    """T from 0.1 to 200 ms, starting at the sampling step (at least 1 ms) and 5 and 25 times it."""
    t0 = max(s.dt, 1e-3)
    return CandidateForm(
        ("damper_lag.T",), {"damper_lag.T": (1e-4, 0.2)}, {"damper_lag.T": t0}, strength=("damper_lag.T",),
        null={"damper_lag.T": 0.0}, starts=tuple({"damper_lag.T": t} for t in (t0, 5 * t0, 25 * t0)), linear=False,
    )  # fmt: skip


EFFECT = Effect(
    "damper_lag",
    "the damper force follows c v through a first-order lag",
    (Param("T", 0.0, 0.0, 1.0, "s", "lag time constant"),),
    strength="T",
    force=force,
    order=80,
    states=1,
    bench=True,
    car_candidate=car,
    bench_candidate=bench,
    resembles={"linear_stiffness": 0.5, "linear_damping": 0.3},  # a lagged damper adds stiffness
)
