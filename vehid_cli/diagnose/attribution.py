"""Attribution: which missing effect explains the residual? A likelihood-ratio test per candidate.

For every effect of the library the config does not declare: a short augmented fit (the current unknowns
plus that effect's parameters, from the current fit, trust-region least squares with a modest budget),
then

* the likelihood-ratio statistic LR = (chi²_before - chi²_with) x R, with chi² the noise-weighted residual
  power per sample over the R training residuals: 2 x the gain in Gaussian log-likelihood with the noise
  sigma of the task (estimated from the data when noise.level is 0); the nested model is the effect
  switched off, so the fit with the effect is never worse than without it (LR >= 0);
* its p-value from chi²(k), k the number of added parameters;
* a BIC margin LR - k ln R (positive: the effect pays for its parameters);
* the validation chi² per sample (the --validate run, else held-out blocks of the data).

A candidate is accepted when p < alpha / (number of candidates) (Bonferroni) AND its validation chi² is
below the current model's. Candidates are ranked by LR, best first.

Search boxes: the effects' physical bounds (effects.py) narrowed to a range a passenger-car strut can have,
so that the short fit starts well scaled; each effect's strength parameter per axle is added, and
asymmetric damping also frees the damping it splits (cf, cr): the data's compression/rebound pair need not
average to the configured damping, and the library's parametrisation keeps that mean at c.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from ..models.effects import EFFECT_NAMES
from ..optimizers.base import BudgetExhausted, Problem, Run
from ..optimizers.lsq import polish

ALPHA = 1e-3  # family-wise significance level of the candidate tests (Bonferroni over candidates)
CANDIDATE_BUDGET = 120  # model evaluations of one candidate's short fit
DISTINCT_VALIDATION = 0.1  # validation J this much lower tells the best candidate from a close runner-up


@dataclass(frozen=True)
class Candidate:
    """How one effect enters a fit: the unknowns it adds, their search range and start."""

    effect: str
    unknowns: tuple[str, ...]  # effect.param names, and vehicle parameters it frees
    limits: dict[str, tuple[float, float]] = field(default_factory=dict)
    start: dict[str, float] = field(default_factory=dict)
    shape: tuple[str, ...] = ()  # further effect parameters freed in the re-fit once the effect is selected
    shape_limits: dict[str, tuple[float, float]] = field(default_factory=dict)


def candidate_specs(config) -> dict[str, Candidate]:
    """The candidate form of each library effect (vehicle values from the config for damping-relative ranges)."""
    v = config.vehicle.values()
    cf, cr = v["cf"], v["cr"]

    def per_axle(effect, param, lo, hi, start=None, companions=(), shape=(), shape_limits=None):
        names = (f"{effect}.{param}_f", f"{effect}.{param}_r")
        limits = {n: (lo(a), hi(a)) for n, a in zip(names, (cf, cr), strict=True)}
        st = {n: start for n in names} if start is not None else {}
        return Candidate(effect, names + tuple(companions), limits, st, shape, shape_limits or {})

    const = lambda x: lambda _c: x  # noqa: E731
    specs = [
        per_axle(
            "asymmetric_damping", "dc", lambda c: -2 * c, lambda c: 2 * c, companions=("cf", "cr"),
            shape=("asymmetric_damping.v_eps",), shape_limits={"asymmetric_damping.v_eps": (1e-3, 0.5)},
        ),
        per_axle(
            "coulomb_friction", "Fc", const(0.0), const(2000.0),
            shape=("coulomb_friction.v_eps",), shape_limits={"coulomb_friction.v_eps": (1e-3, 0.5)},
        ),
        per_axle("progressive_spring", "k3", const(0.0), const(1e9)),
        per_axle("tyre_damping", "ct", const(0.0), const(5000.0)),
        per_axle("hysteresis", "alpha", const(0.0), const(2e6)),
        per_axle("gas_spring", "F0", const(0.0), const(2e4)),
        per_axle("backlash", "gap", const(1e-5), const(0.02), start=1e-4),
        per_axle("damper_lag", "T", const(1e-3), const(0.1), start=3e-3),
    ]  # fmt: skip
    out = {c.effect: c for c in specs}
    assert set(out) == set(EFFECT_NAMES)
    return out


def candidate_ranges(specs: dict[str, Candidate]) -> tuple[dict[str, tuple[float, float]], dict[str, float]]:
    """Every candidate's search ranges (its unknowns' and its shape parameters') and start values, by name."""
    limits: dict[str, tuple[float, float]] = {}
    starts: dict[str, float] = {}
    for c in specs.values():
        limits.update(c.limits)
        limits.update(c.shape_limits)
        starts.update(c.start)
    return limits, starts


@dataclass(frozen=True)
class Fit:
    """A least-squares fit: unknowns, estimate, training chi² per sample, evaluations."""

    names: tuple[str, ...]
    x: NDArray
    J: float
    evaluations: int


def lsq_fit(problem: Problem, x0: NDArray, budget: int, seed: int = 0) -> Fit:
    """Trust-region least squares from x0 within `budget` evaluations (the best point seen)."""
    run = Run(problem, np.random.default_rng(seed), budget)
    try:
        polish(run, x0)
    except BudgetExhausted:
        pass
    x = run.best_x if run.best_x is not None else np.asarray(x0, dtype=float)
    return Fit(tuple(problem.names), x, float(run.best_cost), run.evaluations)


@dataclass(frozen=True)
class Ranked:
    """One candidate's test."""

    effect: str
    added: tuple[str, ...]
    k: int
    J: float  # training chi² per sample reached with the effect
    statistic: float  # likelihood ratio
    p_value: float
    bic_margin: float  # LR - k ln R
    validation_J: float
    accepted: bool
    fit: Fit
    seconds: float

    def to_json(self) -> dict:
        return {
            "effect": self.effect,
            "statistic": self.statistic,
            "p_value": self.p_value,
            "J": self.J,
            "k": self.k,
            "bic_margin": self.bic_margin,
            "validation_J": self.validation_J,
            "accepted": self.accepted,
            "estimates": dict(zip(self.fit.names, map(float, self.fit.x), strict=True)),
        }


def chi2_statistic(residual_count: int) -> Callable[[float, float], float]:
    """LR for a known noise sigma: (chi²_before - chi²_with) x R, J being the chi² per sample."""
    return lambda J0, J1: max(0.0, (J0 - J1) * residual_count)


def rank_candidates(
    candidates: list[Candidate],
    base: Fit,
    base_validation_J: float,
    make_problem: Callable[[tuple[str, ...], Candidate], tuple[Problem, NDArray]],
    validation_J: Callable[[tuple[str, ...], NDArray], float],
    residual_count: int,
    alpha: float = ALPHA,
    budget: int = CANDIDATE_BUDGET,
    statistic: Callable[[float, float], float] | None = None,
    min_gain: float = 0.0,
    claim: bool = True,
) -> list[Ranked]:
    """Test every candidate against the current fit `base`; best (largest LR) first.

    make_problem(names, candidate) gives the augmented problem (its unknowns: names, then the added ones)
    and the start of the added unknowns; validation_J(names, x) the validation J. statistic(J_before, J_with)
    is the LR (default: chi² with known noise over `residual_count` residuals); a candidate must also lower
    the validation J by the fraction `min_gain`; with claim=False nothing is accepted (the data cannot tell)."""
    import time

    statistic = statistic or chi2_statistic(residual_count)
    out = []
    level = alpha / max(len(candidates), 1)
    for cand in candidates:
        t0 = time.perf_counter()
        problem, x_added = make_problem(base.names, cand)
        names = tuple(problem.names)
        added = names[len(base.names) :]
        x0 = np.concatenate([base.x, x_added])
        fit = lsq_fit(problem, x0, budget)
        J = min(fit.J, base.J)  # the nested model (effect off) is always available
        lr = statistic(base.J, J)
        k = len(added)
        p = float(stats.chi2.sf(lr, k))
        vJ = validation_J(names, fit.x) if fit.J < base.J else base_validation_J
        better = np.isfinite(vJ) and vJ < (1.0 - min_gain) * base_validation_J
        accepted = bool(claim and p < level and better)
        out.append(
            Ranked(
                effect=cand.effect, added=added, k=k, J=J, statistic=lr, p_value=p,
                bic_margin=lr - k * math.log(residual_count), validation_J=vJ, accepted=accepted, fit=fit,
                seconds=time.perf_counter() - t0,
            )
        )  # fmt: skip
    out.sort(key=lambda r: -r.statistic)
    return out


def undistinguished(ranked: list[Ranked], best: Ranked, alpha: float = ALPHA) -> Ranked | None:
    """The runner-up the data cannot tell from `best`, if any: another significant candidate whose LR falls
    short of the best's by less than the critical value of a chi²(k_best) test at the per-candidate level
    (the non-nested comparison of two augmented models: the training data must prefer one significantly),
    unless the validation data prefer the best clearly (its validation J DISTINCT_VALIDATION lower)."""
    level = alpha / max(len(ranked), 1)
    margin = float(stats.chi2.isf(level, best.k))
    for r in ranked:
        if r is best or r.p_value >= level:
            continue
        held_out_prefers = best.validation_J < (1.0 - DISTINCT_VALIDATION) * r.validation_J
        if best.statistic - r.statistic < margin and not held_out_prefers:
            return r
    return None
