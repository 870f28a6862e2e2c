"""Tyre damping: f = ct (xd_i - yd_i) [N], a damper beside each tyre spring on the wheel's velocity over the
road's."""

from __future__ import annotations

from .base import SLOT, CandidateForm, CarScale, Effect, Param, constant, per_axle_candidate


def force(x, v, c, i, p, z, zd, f, damper):
    """Its force on strut i (the contract: models/effects/base.py)."""
    if p[SLOT.on] != 0.0:
        f += p[SLOT.ct + i] * v
    return f, damper


def car(s: CarScale) -> CandidateForm:
    """ct per axle up to 5 kN s/m."""
    return per_axle_candidate("tyre_damping", "ct", constant(0.0), constant(5000.0), s)


EFFECT = Effect(
    "tyre_damping",
    "a damper beside each tyre spring, on wheel minus road velocity",
    (Param("ct", 0.0, 0.0, 1e5, "N s/m", "tyre damping"),),
    strength="ct",
    force=force,
    order=40,
    tyre=True,
    car_candidate=car,
    resembles={"linear_damping": 0.3},
)
