"""diagnose/claims.py: the swap and pair tests on a linear toy whose fits and likelihood ratios are closed-form.

The toy: y = c0 u0 + kf u1 (+ hyst.a u1 + hyst.b u2) + unit noise, J the chi² per sample. The effect `hyst` can
imitate a mis-set kf (its `a` along u1) and adds a direction of its own (u2); the known parameter kf has only u1.
The pair toy: y = c0 u0 + kf u1 + cr u2 (+ hyst.a u1 + hyst.b u2 + hyst.c u3): the effect's three unknowns span both
known parameters' directions and one of its own."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from vehid_cli.diagnose.attribution import (
    Candidate,
    Fit,
    Ranked,
    chi2_statistic,
    fit_free,
    parameter_candidate,
    undistinguished,
)
from vehid_cli.diagnose.claims import PARSIMONY_SHARE, SWAP_SHARE, pair_test, rival, swap_test
from vehid_cli.diagnose.loop import _Augmentation
from vehid_cli.diagnose.subject import Subject
from vehid_cli.diagnose.tails import chi2_isf
from vehid_cli.optimizers.base import Problem

R = 4000
KF = 1.0  # kf's configured value
LIMITS = {"c0": (-10.0, 10.0), "kf": (0.0, 10.0), "cr": (0.0, 10.0)} | {f"hyst.{c}": (-10.0, 10.0) for c in "abc"}
START = {"c0": 0.0, "kf": KF, "cr": KF, "hyst.a": 0.0, "hyst.b": 0.0, "hyst.c": 0.0}
ROWS = {"c0": 0, "kf": 1, "hyst.a": 1, "hyst.b": 2}  # the direction u[row] each unknown scales
PAIR_ROWS = ROWS | {"cr": 2, "hyst.c": 3}
EFFECT = Candidate("hyst", ("hyst.a", "hyst.b"), strength=("hyst.a", "hyst.b"))
LEVEL = 0.05 / 3


def toy(y: np.ndarray, u: np.ndarray, rows: dict[str, int] = ROWS) -> Subject:
    """The toy's subject: the problem over any unknowns (the others at their configured value or zero)."""

    def problem_for(names: tuple[str, ...]) -> tuple[Problem, np.ndarray]:
        idx = {n: j for j, n in enumerate(names)}

        def residuals(X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            X = np.atleast_2d(X)
            v = {n: X[:, idx[n]][:, None] if n in idx else START[n] for n in rows}
            model = sum(v[n] * u[row] for n, row in rows.items())
            r = model - y  # unit noise: the residual is weighted already
            return (r**2).mean(axis=1), r

        lower = np.array([LIMITS[n][0] for n in names])
        upper = np.array([LIMITS[n][1] for n in names])
        problem = Problem(lower, upper, lambda X: residuals(X)[0], residuals, names=names)
        return problem, np.array([START[n] for n in names])

    specs = {"hyst": EFFECT} | {f"parameter:{n}": parameter_candidate(n, KF) for n in ("kf", "cr")}
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


def ranked(effect: str, kind: str, lr: float, fit: Fit, accepted: bool = True, added: tuple[str, ...] = ()) -> Ranked:
    added = added or (("kf",) if kind == "parameter" else ("hyst.a", "hyst.b"))
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


def pair_round(kf: float, cr: float, own: float, seed: int = 5):
    """The pair toy's round against c0 alone: the subject, the current fit, the ranked effect (three unknowns) and
    known parameters kf, cr (each alone) with their LRs from the fits, and the toy's directions u and data y."""
    rng = np.random.default_rng(seed)
    u = rng.standard_normal((4, R))
    y = 2.0 * u[0] + kf * u[1] + cr * u[2] + own * u[3] + rng.standard_normal(R)
    subject = toy(y, u, PAIR_ROWS)
    current = fitted(subject, ("c0",))
    lr = chi2_statistic(R)
    rounds = []
    for effect, kind, names in [
        ("hyst", "effect", ("hyst.a", "hyst.b", "hyst.c")),
        ("parameter:kf", "parameter", ("kf",)),
        ("parameter:cr", "parameter", ("cr",)),
    ]:
        fit = fitted(subject, ("c0", *names))
        rounds.append(ranked(effect, kind, lr(current.J, fit.J), fit, added=names))
    return subject, current, sorted(rounds, key=lambda r: -r.statistic), u, y


def test_two_mis_set_parameters_together_are_preferred_to_an_effect_that_spans_both():
    subject, current, ranked_, u, y = pair_round(kf=1.6, cr=1.5, own=0.0)
    best = ranked_[0]
    assert best.effect == "hyst"  # the effect beats each parameter alone (it spans both directions)
    assert all(r.statistic < PARSIMONY_SHARE * best.statistic for r in ranked_[1:])  # single parsimony cannot apply
    pair = pair_test(subject, current, ranked_, best, LEVEL, 400)
    assert pair is not None and pair.first.effect == "parameter:kf" and pair.second.effect == "parameter:cr"
    # the closed form: the pair's LR is R times the fall of the mean squared residual, from c0 alone (kf, cr at their
    # configured KF) to least squares on u0 .. u2
    known = y - KF * (u[1] + u[2])
    ss = [np.mean((z - u[:n].T @ np.linalg.lstsq(u[:n].T, z, rcond=None)[0]) ** 2) for z, n in ((known, 1), (y, 3))]
    assert pair.statistic == pytest.approx(R * (ss[0] - ss[1]), rel=1e-6)
    assert best.statistic - pair.statistic < pair.critical == pytest.approx(float(chi2_isf(LEVEL, 3)))
    assert "parameter:kf and parameter:cr together explain the residual as well as hyst" in pair.describe()


def test_a_real_effect_beside_two_mis_set_parameters_is_not_given_to_the_pair():
    subject, current, ranked_, _, _ = pair_round(kf=1.6, cr=1.5, own=0.8)
    assert ranked_[0].effect == "hyst"
    assert pair_test(subject, current, ranked_, ranked_[0], LEVEL, 400) is None


def test_no_pair_test_without_two_accepted_parameters_or_where_the_effect_has_one_unknown():
    subject, current, ranked_, _, _ = pair_round(kf=1.6, cr=1.5, own=0.0)
    best, first, second = ranked_
    refused = ranked(second.effect, "parameter", second.statistic, second.fit, accepted=False, added=second.added)
    assert pair_test(subject, current, [best, first, refused], best, LEVEL, 400) is None
    small = ranked("hyst", "effect", best.statistic, best.fit, added=("hyst.a",))
    assert pair_test(subject, current, [small, first, second], small, LEVEL, 400) is None
    assert pair_test(subject, current, ranked_, first, LEVEL, 400) is None  # a parameter won: nothing to test


def test_the_loop_claims_the_pairs_first_though_its_second_is_as_strong():
    """_Augmentation.choose: with the pair preferred to the effect, the pair's second (its LR within the critical
    value of the first's, so `undistinguished` alone would refuse both) is no rival: the first is chosen."""
    subject, current, ranked_, _, _ = pair_round(kf=1.6, cr=1.5, own=0.0)
    best, first, second = ranked_
    close = dataclasses.replace(second, statistic=first.statistic - 1.0)
    loop = _Augmentation(subject, 0.05, 400, 400, True, lambda _s: None, [], current, (0.0, None))
    chosen = loop.choose([best, first, close], (subject, current, (0.0, None)))
    assert chosen is first and "together explain the residual as well as hyst" in loop.notes[0]
    assert undistinguished([best, first, close], first, 0.05) is close  # what the pair's exception overrides
    loop = _Augmentation(subject, 0.05, 400, 400, True, lambda _s: None, [], current, (0.0, None))
    other = dataclasses.replace(close, effect="parameter:x")  # a third parameter as strong: no choice
    assert loop.choose([best, first, close, other], (subject, current, (0.0, None))) is None
