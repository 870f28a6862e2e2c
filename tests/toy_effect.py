"""A toy effect in one file, outside the package: a quadratic damper beside each strut, f = cq v |v| [N] (the law a
hydraulic orifice gives). `tests/test_effects.py` registers it and checks that the whole machine takes it."""

from __future__ import annotations

import numpy as np

from vehid_cli.models.effects import Effect, Param, Shape
from vehid_cli.models.effects.base import SLOT, constant, per_axle_candidate


def force(x, v, c, i, p, z, zd, f, damper):
    """f += cq v |v| on strut i (models/effects/base.py: the contract)."""
    if p[SLOT.on] != 0.0:
        f += p[SLOT.cq + i] * v * abs(v)
    return f, damper


EFFECT = Effect(
    "toy_quadratic_damper",
    "a quadratic damper beside the strut, f = cq v |v|",
    (Param("cq", 0.0, 0.0, 1e6, "N s^2/m^2", "quadratic damping coefficient"),),
    strength="cq",
    force=force,
    order=35,
    car_candidate=lambda s: per_axle_candidate("toy_quadratic_damper", "cq", constant(0.0), constant(5e4), s),
    shapes=(Shape("toy_quadratic", "velocity", lambda x: [(np.abs(x) * x, 0, "")], rank=9),),
    resembles={"toy_quadratic": 1.0, "quadratic_damping": 1.0},
)
