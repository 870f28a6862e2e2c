"""The diagnosis's fits of the linear car on its exact sensitivities (an exact-integrator twin of the task:
diagnosis.exact_twin, holdout.masked's linearisation, attribution.linear_fit) and the effects' score statistic
(score.effect_score), each against an independent truth: central differences of the masked residuals, the
trust-region fit on the diagnosis's own (rk4) problem, the likelihood ratio of the fitted candidate."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from vehid_cli.config import load_config
from vehid_cli.diagnose.attribution import (
    SCREEN_TOL,
    Z95,
    Ranked,
    candidate_fit,
    candidate_specs,
    fit_free,
    fit_intervals,
    linear_fit,
    lsq_fit,
    screenable,
)
from vehid_cli.diagnose.holdout import masked
from vehid_cli.diagnose.score import cannot_win, effect_score, fitted_basis
from vehid_cli.identify.task import build_task
from vehid_cli.sim.sensitivity import central_points
from vehid_cli.systems.vehicle.diagnosis import exact_twin, holdout_mask, prepare_config

BASE = Path(__file__).resolve().parents[1] / "configs" / "gokdag2015" / "base.yaml"
NOISE = ["identify.objective=wls", "noise.level=0.03", "identify.truth=config"]


def case(*truth_sets: str):
    """The diagnosis's task (rk4, held-out blocks masked) on data of a car with `truth_sets`, its twin and masks."""
    truth = build_task(prepare_config(load_config(BASE, [*NOISE, *truth_sets])))
    task = dataclasses.replace(build_task(prepare_config(load_config(BASE, NOISE))), sigma=truth.sigma)
    ref = truth.reference(0)
    keep = ~holdout_mask(task, ref)
    return task, ref, keep


def test_masked_linearisation_equals_central_differences_of_the_masked_residuals():
    task, ref, keep = case("vehicle.kf=54000")
    problem = masked(exact_twin(task).problem(ref), keep)
    x = task.nominal
    cost, r, jac = problem.linearised(x)
    c0, r0 = problem.residuals(x[None, :])
    assert r.shape == (int(keep.sum()),)
    assert abs(cost - c0[0]) <= 1e-12 * c0[0]
    np.testing.assert_allclose(r, r0[0], rtol=0, atol=1e-9 * np.abs(r0).max())
    h = 1e-6 * np.abs(x)
    X = central_points(x, h)
    _, R = problem.residuals(X)
    D = x.size
    fd = ((R[:D] - R[D:]) / (2 * h[:, None])).T
    assert np.linalg.norm(jac - fd) <= 1e-5 * np.linalg.norm(fd)


@pytest.mark.parametrize("extra", [(), ("kf",), ("cr",)])
def test_linear_fit_reaches_the_trust_region_fit_on_the_diagnosis_problem(extra):
    """LM on the exact integrator, J on rk4: the LR it gives differs from the rk4 fit's by far less than 0.01."""
    task, ref, keep = case("vehicle.kf=54000", "vehicle.cr=2975")
    t = task.with_unknowns(list(extra)) if extra else task
    problem = masked(t.problem(ref), keep)
    linear = masked(exact_twin(t).problem(ref), keep)
    got = linear_fit(problem, linear, t.nominal, 100)
    want = lsq_fit(problem, t.nominal, 600)
    R = int(keep.sum())
    assert got is not None and got.evaluations < 30
    assert abs(R * (got.J - want.J)) < 1e-2, (got.J, want.J)
    sd = fit_intervals(problem, want, want.J) / Z95  # the estimate's standard deviation, the residual's own variance
    assert np.all(np.abs(got.x - want.x) < 0.05 * sd), np.abs(got.x - want.x) / sd


def test_linear_fit_on_a_search_bound_is_finished_by_the_trust_region_on_the_exact_integrator():
    """A known parameter driven onto its bound: LM clips its steps there, so the trust region (which handles the
    bounds) finishes the fit on the exact integrator; it reaches the rk4 trust region's fit (the LR to far less than
    0.01, the estimate to a small fraction of its standard deviation) at a fraction of its simulations."""
    task, ref, keep = case("vehicle.kf=54000", "vehicle.cr=2975")
    t = task.with_unknowns(["kR"])
    problem = masked(t.problem(ref), keep)
    linear = masked(exact_twin(t).problem(ref), keep)
    trf = lsq_fit(problem, t.nominal, 600, tol=SCREEN_TOL)
    assert np.isclose(trf.x[-1], problem.upper[-1], rtol=1e-9)  # the case tests something: kR ends on its bound
    rk4_runs = []
    counted = dataclasses.replace(problem, cost=lambda X: rk4_runs.append(len(X)) or problem.cost(X))
    got = linear_fit(counted, linear, t.nominal, 100)
    assert got is not None and np.isclose(got.x[-1], problem.upper[-1], rtol=1e-9)
    assert rk4_runs == [1]  # only its J on the rk4 integrator
    assert abs(int(keep.sum()) * (got.J - trf.J)) < 1e-2, (got.J, trf.J)
    sd = fit_intervals(problem, trf, trf.J) / Z95
    free = np.arange(got.x.size - 1)  # (kR, on its bound, has no interval to compare with)
    assert np.all(np.abs(got.x - trf.x)[free] < 0.05 * sd[free]), np.abs(got.x - trf.x) / sd

    def normal(x):  # the same problem as a long record's: its normal equations only
        cost, r, jac = linear.linearised(x)
        return cost, r, jac.T @ jac, jac.T @ r

    summed = dataclasses.replace(linear, linearised=None, normal=normal)
    assert linear_fit(problem, summed, t.nominal, 100) is None  # no (R, D) Jacobian made: the caller's blocked fit
    assert linear_fit(problem, linear, t.nominal, 100, bounds=False) is None  # stoppable: the caller fits it


def test_intervals_from_exact_sensitivities_are_the_central_differences_ones():
    """fit_intervals with the linear car's exact-integrator twin (J'J from one simulation with sensitivities) against
    the rk4 problem's central-difference Jacobian (the truth to ~1e-7 here): the same to 1e-4, closer than the
    forward differences it replaces; an unknown held fixed still has none."""
    task, ref, keep = case("vehicle.kf=54000", "vehicle.cr=2975")
    t = task.with_unknowns(["kf"])
    problem = masked(t.problem(ref), keep)
    linear = masked(exact_twin(t).problem(ref), keep)
    fit = lsq_fit(problem, t.nominal, 600)
    h = 1e-5 * np.abs(fit.x)
    _, R = problem.residuals(central_points(fit.x, h))
    D = fit.x.size
    J = ((R[:D] - R[D:]) / (2 * h[:, None])).T
    truth = Z95 * np.sqrt(np.diag(np.linalg.inv(J.T @ J)) * fit.J)
    exact = fit_intervals(problem, fit, fit.J, linear)
    forward = fit_intervals(problem, fit, fit.J)
    np.testing.assert_allclose(exact, truth, rtol=1e-4)
    assert np.max(np.abs(exact / truth - 1)) < np.max(np.abs(forward / truth - 1))
    held = dataclasses.replace(fit, fixed=("kf",))
    assert np.isnan(fit_intervals(problem, held, fit.J, linear)[-1])


@pytest.mark.parametrize(("effect", "truth"), [
    ("tyre_damping", ("vehicle.effects.tyre_damping.ct_f=300", "vehicle.effects.tyre_damping.ct_r=300")),
    ("coulomb_friction", ("vehicle.kf=54000",)),
])  # fmt: skip
def test_effect_score_is_the_fitted_likelihood_ratio_to_first_order(effect, truth):
    """A weak effect in the data: the score at zero strength against the fitted LR; a spring mis-set instead:
    the friction's two-sided score is large but a friction cannot be negative, and the one-sided score, like the
    fitted LR, is near zero."""
    sets = (*truth, "simulation.integrator=rk4") if "effects" in truth[0] else truth
    task, ref, keep = case(*sets)
    problem = masked(task.problem(ref), keep)
    declared = lsq_fit(problem, task.nominal, 600)
    cfg = prepare_config(load_config(BASE, NOISE))
    cand = candidate_specs(cfg, cfg.simulation.dt)[effect]
    aug = task.with_unknowns(list(cand.unknowns + cand.shape), limits={**cand.limits, **cand.shape_limits},
                             start=cand.start)  # fmt: skip
    cproblem = masked(aug.problem(ref), keep)
    D = task.dim
    x0 = np.concatenate([declared.x, aug.nominal[D:]])
    basis = fitted_basis(problem, declared.x, np.ones(D, dtype=bool))
    S = effect_score(cproblem, x0, cand, basis)
    x0[[cproblem.names.index(n) for n in cand.strength]] = 0.0
    free = np.array([n not in cand.shape for n in cproblem.names])
    fitted = fit_free(cproblem, x0, free, 400)
    R = int(keep.sum())
    LR = max(0.0, (declared.J - fitted.J) * R)
    assert abs(S - LR) <= 0.1 * LR + 2.0, (S, LR)
    if effect == "tyre_damping":
        assert LR > 20.0  # the case tests something: an effect the test detects
    else:  # and the one-sided score is what spares the fit: the two-sided one is far above the critical LR
        cproblem_two_sided = dataclasses.replace(cproblem, lower=cproblem.lower - (cproblem.upper - cproblem.lower))
        assert effect_score(cproblem_two_sided, x0, cand, basis) > 100.0


@pytest.mark.slow
def test_effects_that_cannot_win_would_have_lost_to_the_parameter():
    """A front spring 20 % off: the effects score.cannot_win spares are fitted anyway, and each fitted LR is below the
    spring's (the premise of not fitting them: the round's best is the parameter whatever their fits give)."""
    task, ref, keep = case("vehicle.kf=54000")
    problem = masked(task.problem(ref), keep)
    declared = lsq_fit(problem, task.nominal, 600)
    R, D = int(keep.sum()), task.dim
    with_kf = task.with_unknowns(["kf"])
    kf = linear_fit(masked(with_kf.problem(ref), keep), masked(exact_twin(with_kf).problem(ref), keep),
                    np.concatenate([declared.x, with_kf.nominal[D:]]), 100)  # fmt: skip
    best = (declared.J - kf.J) * R
    cfg = prepare_config(load_config(BASE, NOISE))
    specs = candidate_specs(cfg, cfg.simulation.dt)
    basis = fitted_basis(problem, declared.x, np.ones(D, dtype=bool))
    scores, problems = {}, {}
    for cand in (c for c in specs.values() if screenable(c)):
        aug = task.with_unknowns(list(cand.unknowns + cand.shape), limits={**cand.limits, **cand.shape_limits},
                                 start=cand.start)  # fmt: skip
        problems[cand.effect] = masked(aug.problem(ref), keep), aug.nominal[D:]
        S = effect_score(problems[cand.effect][0], np.concatenate([declared.x, aug.nominal[D:]]), cand, basis)
        scores[cand.effect] = (S, tuple(problems[cand.effect][0].names[D:]))
    ranked = Ranked("parameter:kf", ("kf",), 1, kf.J, best, 0.0, 0.0, 1.0, True, kf, 0.0, kind="parameter")
    _, beaten = cannot_win(list(specs.values()), scores, [ranked], declared, (1.0, None), lambda k: 20.0, R)
    assert len(beaten) >= 2  # the case tests something
    for r in beaten:
        cproblem, x_added = problems[r.effect]
        fitted = candidate_fit(cproblem, declared, x_added, specs[r.effect], 150, declared.J)
        assert (declared.J - fitted.J) * R < best, (r.effect, r.statistic, (declared.J - fitted.J) * R, best)
