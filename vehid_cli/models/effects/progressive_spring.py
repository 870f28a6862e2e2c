"""A progressive spring: cubic stiffening f = k3 d³ [N] beside the linear spring."""

from __future__ import annotations

from .base import SLOT, CandidateForm, CarScale, Effect, Param, Shape, constant, per_axle_candidate


def force(x, v, c, i, p, z, zd, f, damper):
    """Its force on strut i (the contract: models/effects/base.py)."""
    if p[SLOT.on] != 0.0:
        f += p[SLOT.k3 + i] * x * x * x
    return f, damper


def car(s: CarScale) -> CandidateForm:
    """k3 per axle up to 1e9 N/m³."""
    return per_axle_candidate("progressive_spring", "k3", constant(0.0), constant(1e9), s)


EFFECT = Effect(
    "progressive_spring",
    "cubic stiffening k3 d^3 beside the linear spring",
    (Param("k3", 0.0, 0.0, 1e12, "N/m^3", "cubic stiffness"),),
    strength="k3",
    force=force,
    order=30,
    bench=True,
    car_candidate=car,
    shapes=(Shape("progressive_spring", "deflection", lambda x: [(x**3, 1, "")], rank=1),),
    resembles={"progressive_spring": 1.0, "gas_spring": 0.5, "dead_band": 0.5},
)
