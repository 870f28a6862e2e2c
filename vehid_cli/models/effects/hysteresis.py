"""Hysteresis: a Bouc-Wen element (n = 2) beside the spring, f = alpha z [N], with one state per strut,
zd = A v - beta v z² - gamma |v| z |z| (z [m] saturates at sqrt(A / (beta + gamma)))."""

from __future__ import annotations

from collections.abc import Sequence

from .base import SLOT, BenchScale, CandidateForm, CarScale, Effect, Param, constant, per_axle_candidate


def force(x, v, c, i, p, z, zd, f, damper):
    """Its force on strut i (the contract: models/effects/base.py)."""
    if p[SLOT.on] != 0.0:
        j = int(p[SLOT.z]) + i
        zz = z[j]
        f += p[SLOT.alpha + i] * zz
        zd[j] = p[SLOT.A] * v - p[SLOT.beta] * v * zz * zz - p[SLOT.gamma] * abs(v) * zz * abs(zz)
    return f, damper


def yield_starts(yields_m: Sequence[float], A: float = 1.0) -> tuple[dict[str, float], ...]:
    """Bouc-Wen starts (beta = gamma) whose hysteretic state saturates at each yield displacement [m]."""
    return tuple({"hysteresis.beta": A / (2 * y * y), "hysteresis.gamma": A / (2 * y * y)} for y in yields_m)


def car(s: CarScale) -> CandidateForm:
    """alpha per axle up to 2e6 N/m; loops that yield between 0.5 and 20 mm."""
    return per_axle_candidate(
        "hysteresis", "alpha", constant(0.0), constant(2e6), s,
        shape_limits={"hysteresis.beta": (1e3, 2e6), "hysteresis.gamma": (1e3, 2e6)},
        starts=yield_starts((0.001, 0.003, 0.008, 0.018)),
    )  # fmt: skip


def bench(s: BenchScale) -> CandidateForm:
    """alpha up to 20 F over the narrowest loop; loop widths from 3 % to 80 % of the stroke's spread."""
    zsat = 0.2 * s.X  # z saturates at sqrt(1 / (beta + gamma)): a fifth of the stroke to start
    bg = 0.5 / zsat**2
    lo, hi = 0.5 / max(s.yields) ** 2 / 4, 0.5 / min(s.yields) ** 2 * 4
    return CandidateForm(
        ("hysteresis.alpha",), {"hysteresis.alpha": (0.0, 20.0 * s.F / min(s.yields))},
        {"hysteresis.alpha": 0.0, "hysteresis.beta": bg, "hysteresis.gamma": bg},
        ("hysteresis.beta", "hysteresis.gamma"), {"hysteresis.beta": (lo, hi), "hysteresis.gamma": (lo, hi)},
        strength=("hysteresis.alpha",),
        null={"hysteresis.alpha": 0.0},
        starts=tuple({"hysteresis.beta": 0.5 / y**2, "hysteresis.gamma": 0.5 / y**2} for y in s.yields),
    )  # fmt: skip


EFFECT = Effect(
    "hysteresis",
    "Bouc-Wen (n = 2) in the strut, f = alpha z",
    (
        Param("alpha", 0.0, 0.0, 1e7, "N/m", "Bouc-Wen force per unit z"),
        Param("beta", 2e4, -1e12, 1e12, "1/m^2", "Bouc-Wen shape (beta + gamma > 0)", per_axle=False),
        Param("gamma", 2e4, -1e12, 1e12, "1/m^2", "Bouc-Wen shape", per_axle=False),
        Param("A", 1.0, 0.0, 100.0, "-", "Bouc-Wen initial slope dz/dd", per_axle=False),
    ),
    strength="alpha",
    force=force,
    order=60,
    states=1,
    bench=True,
    car_candidate=car,
    bench_candidate=bench,
    resembles={"linear_stiffness": 0.4, "coulomb_friction": 0.7, "sqrt_damper": 0.4},  # saturated loops: friction
)
