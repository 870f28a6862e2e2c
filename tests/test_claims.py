"""diagnose/claims.py: the swap test on a linear toy whose fits and likelihood ratios are closed-form.

The toy: y = c0 u0 + kf u1 (+ hyst.a u1 + hyst.b u2) + unit noise, J the chi² per sample. The effect `hyst` can
imitate a mis-set kf (its `a` along u1) and adds a direction of its own (u2); the known parameter kf has only u1."""

from __future__ import annotations

import numpy as np
import pytest

from vehid_cli.diagnose.attribution import Candidate, Fit, Ranked, chi2_statistic, fit_free, parameter_candidate
from vehid_cli.diagnose.claims import SWAP_SHARE, rival, swap_test
from vehid_cli.diagnose.subject import Subject
from vehid_cli.diagnose.tails import chi2_isf
from vehid_cli.optimizers.base import Problem

R = 4000
KF = 1.0  # kf's configured value
LIMITS = {"c0": (-10.0, 10.0), "kf": (0.0, 10.0), "hyst.a": (-10.0, 10.0), "hyst.b": (-10.0, 10.0)}
START = {"c0": 0.0, "kf": KF, "hyst.a": 0.0, "hyst.b": 0.0}
EFFECT = Candidate("hyst", ("hyst.a", "hyst.b"), strength=("hyst.a", "hyst.b"))
LEVEL = 0.05 / 3


def toy(y: np.ndarray, u: np.ndarray) -> Subject:
    """The toy's subject: the problem over any unknowns (the others at their configured value or zero)."""

    def problem_for(names: tuple[str, ...]) -> tuple[Problem, np.ndarray]:
        idx = {n: j for j, n in enumerate(names)}

        def residuals(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            X = np.atleast_2d(X)
            v = {n: X[:, idx[n]][:, None] if n in idx else START[n] for n in START}
            model = v["c0"] * u[0] + (v["kf"] + v["hyst.a"]) * u[1] + v["hyst.b"] * u[2]
            r = model - y  # unit noise: the residual is weighted already
            return (r**2).mean(axis=1), r

        lower = np.array([LIMITS[n][0] for n in names])
        upper = np.array([LIMITS[n][1] for n in names])
        problem = Problem(lower, upper, lambda X: residuals(X)[0], residuals, names=names)
        return problem, np.array([START[n] for n in names])

    specs = {"hyst": EFFECT, "parameter:kf": parameter_candidate("kf", KF)}
    return Subject(
        specs=specs, declared=frozenset(), problem_for=problem_for, validation_J=lambda names, x: (0.0, None),
        residual_count=R, statistic=lambda _fit: chi2_statistic(R), scale=lambda f: f.J,
    )  # fmt: skip


def data(effect_b: float, seed: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """u (3, R) and y: c0 = 2, kf = 3 (configured 1), and `effect_b` along the effect's own direction u2."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((3, R))
    return 2.0 * u[0] + 3.0 * u[1] + effect_b * u[2] + rng.standard_normal(R), u


def fitted(subject: Subject, names: tuple[str, ...]) -> Fit:
    problem, start = subject.problem_for(names)
    return fit_free(problem, start, np.ones(len(names), dtype=bool), 400)


def ranked(effect: str, kind: str, lr: float, fit: Fit, accepted: bool = True) -> Ranked:
    added = ("kf",) if kind == "parameter" else ("hyst.a", "hyst.b")
    return Ranked(effect=effect, added=added, k=len(added), J=fit.J, statistic=lr, p_value=0.0, bic_margin=lr,
                  validation_J=0.0, accepted=accepted, fit=fit, seconds=0.0, kind=kind)  # fmt: skip


def test_an_effect_that_only_imitated_a_mis_set_parameter_is_swapped_for_it():
    y, u = data(effect_b=0.0)
    subject = toy(y, u)
    current = fitted(subject, ("c0", "hyst.a", "hyst.b"))
    param = ranked("parameter:kf", "parameter", 1.0, fitted(subject, ("c0", "kf")))

    def never() -> Fit:
        raise AssertionError("the model with neither is not needed when the effect's LR over the swap is short")

    swap = swap_test(subject, current, EFFECT, param, never, LEVEL, 400)
    assert swap is not None and swap.parameter == "parameter:kf" and swap.share is None
    assert swap.fit.names == ("c0", "kf")
    # the closed form: the least-squares kf, and the effect's LR over it one chi²(1) draw (its extra u2 direction)
    beta = np.linalg.lstsq(u[:2].T, y, rcond=None)[0]
    assert swap.fit.x == pytest.approx(beta, rel=1e-6)
    assert swap.gap == pytest.approx(R * (swap.fit.J - current.J), abs=1e-6)
    assert swap.gap < swap.critical == pytest.approx(float(chi2_isf(LEVEL, 2)))
    assert "hyst swapped for parameter:kf" in swap.describe(current.J)


def test_a_real_effect_is_kept_when_the_parameter_explains_less_than_the_parsimony_share():
    y, u = data(effect_b=1.5)
    subject = toy(y, u)
    current = fitted(subject, ("c0", "hyst.a", "hyst.b"))
    neither = fitted(subject, ("c0",))
    param = ranked("parameter:kf", "parameter", 1.0, fitted(subject, ("c0", "kf")))
    asked = []
    swap = swap_test(subject, current, EFFECT, param, lambda: asked.append(1) or neither, LEVEL, 400)
    assert swap is None and asked == [1]  # the share was needed, and the parameter's (about 4 / 6.25) falls short


def test_the_rival_is_the_strongest_accepted_parameter_of_the_effects_round_within_the_share():
    y, u = data(effect_b=0.0)
    subject = toy(y, u)
    fit = fitted(subject, ("c0",))
    effect = ranked("hyst", "effect", 100.0, fit)
    strong = ranked("parameter:kf", "parameter", SWAP_SHARE * 100.0, fit)
    weak = ranked("parameter:kf", "parameter", SWAP_SHARE * 100.0 - 1.0, fit)
    refused = ranked("parameter:kf", "parameter", 99.0, fit, accepted=False)
    assert rival([(effect, strong)], "hyst", ("c0",)) is strong
    assert rival([(effect, weak)], "hyst", ("c0",)) is None
    assert rival([(effect, refused)], "hyst", ("c0",)) is None
    assert rival([(effect, strong)], "hyst", ("c0", "kf")) is None  # kf is in the model already
    assert rival([(effect, weak), (strong,)], "hyst", ("c0",)) is None  # the round that ranked the effect last
