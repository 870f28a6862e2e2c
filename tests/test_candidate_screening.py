"""The candidate fits' savings of simulations (issue 26): Broyden's update, the screening of the starts with shared and
approximate car columns, trf's unused last Jacobian and the longest-first order of the parallel fits; each against
an independent truth (the secant condition, a closed-form least squares, scipy's own run, the serial order)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.test_diagnose_exact import BASE, NOISE, case
from vehid_cli.config import load_config
from vehid_cli.diagnose import attribution as A
from vehid_cli.diagnose import starts as S
from vehid_cli.diagnose.holdout import masked
from vehid_cli.diagnose.score import fitted_basis
from vehid_cli.optimizers import lsq
from vehid_cli.optimizers.base import Problem, Search
from vehid_cli.systems.vehicle.diagnosis import prepare_config


def counted(problem: Problem) -> tuple[Problem, list[int]]:
    """The problem with a count of the points its residuals were asked for."""
    n = [0]

    def residuals(X):
        n[0] += len(X)
        return problem.residuals(X)

    return Problem(problem.lower, problem.upper, lambda X: residuals(X)[0], residuals, names=problem.names), n


def linear_problem(seed: int = 0) -> tuple[Problem, np.ndarray, np.ndarray]:
    """r = A x - y over 4 'car' unknowns and 2 'effect' strengths (the effect's columns scaled by a shape unknown, the
    last): cost the mean square; its matrix A (at shape 1) and data y."""
    rng = np.random.default_rng(seed)
    A_ = rng.standard_normal((200, 6))
    y = A_ @ np.array([1.0, -2.0, 0.5, 3.0, 0.7, -0.4]) + 0.01 * rng.standard_normal(200)

    def residuals(X):
        X = np.atleast_2d(X)
        R = X[:, :4] @ A_[:, :4].T + (X[:, 4:6] * X[:, 6:7]) @ A_[:, 4:6].T - y
        return np.mean(R**2, axis=1), R

    lo, hi = np.r_[-10 * np.ones(6), 0.5], np.r_[10 * np.ones(6), 2.0]
    names = ("a", "b", "c", "d", "e.s1", "e.s2", "e.shape")
    return Problem(lo, hi, lambda X: residuals(X)[0], residuals, names=names), A_, y


def test_broyden_update_reproduces_the_secant_and_leaves_other_directions():
    rng = np.random.default_rng(3)
    J, dx, dr = rng.standard_normal((50, 4)), rng.standard_normal(4), rng.standard_normal(50)
    width = np.array([1.0, 1e3, 1e-2, 10.0])
    new = S.broyden(J, dx, dr, width)
    np.testing.assert_allclose(new @ dx, dr, rtol=1e-10, atol=1e-10)  # the secant condition
    du = dx / width
    v = rng.standard_normal(4)
    v -= (v @ du) / (du @ du) * du  # orthogonal to the step in box-width units
    np.testing.assert_allclose(new @ (v * width), J @ (v * width), rtol=1e-10, atol=1e-10)
    assert np.array_equal(S.broyden(J, np.zeros(4), dr, width), J)  # no step, no update


@pytest.mark.parametrize("secant", [False, True])
def test_screening_reaches_the_least_squares_solution(monkeypatch, secant):
    """On a model linear in the car's unknowns and the strengths, three damped Gauss-Newton steps from each start
    reach the closed-form least squares over the unknowns it steps (the shape held), with the car's columns by forward
    differences or from the current fit's Jacobian."""
    monkeypatch.setattr(S, "SECANT", secant)
    problem, A_, y = linear_problem()
    x0 = np.r_[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
    starts = ({"e.shape": 1.0}, {"e.shape": 1.5})
    car = A_[:, :4]  # the current fit's Jacobian along the car's unknowns (exact: linear)
    got = S.screen_starts(problem, x0, starts, ("e.shape",), ("e.s1", "e.s2"), {}, True, 4, car)
    for shape in (1.0, 1.5):
        M = np.c_[A_[:, :4], shape * A_[:, 4:6]]
        x = np.linalg.lstsq(M, y, rcond=None)[0]
        if got[6] == shape:
            np.testing.assert_allclose(got[:6], x, rtol=1e-4, atol=1e-6)
    assert got[6] in (1.0, 1.5)


def test_shared_force_free_starts_change_nothing_and_save_simulations(monkeypatch):
    """Starts whose strengths are at null share the response and the car's derivatives: the same point, bit for bit,
    as when every start is differenced on its own (the effect declared nonlinear), with fewer simulations."""
    monkeypatch.setattr(S, "SECANT", False)
    problem, _, _ = linear_problem(1)
    x0 = np.r_[0.3, -0.2, 0.1, 0.4, 0.0, 0.0, 1.0]
    starts = tuple({"e.shape": s} for s in (0.6, 1.0, 1.4, 1.9))
    got = {}
    for linear in (False, True):
        p, n = counted(problem)
        got[linear] = (S.screen_starts(p, x0, starts, ("e.shape",), ("e.s1", "e.s2"), {}, linear, 4), n[0])
    assert np.array_equal(got[True][0], got[False][0])
    assert got[True][1] <= got[False][1] - 3 * 4  # 3 starts' car columns (4 each) not simulated again


def decaying(seed: int = 0) -> Problem:
    """Fit y = a exp(-b t) + c to noisy samples: a small nonlinear least squares."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 4, 120)
    y = 2.0 * np.exp(-1.3 * t) + 0.5 + 0.02 * rng.standard_normal(t.size)

    def residuals(X):
        X = np.atleast_2d(X)
        R = X[:, :1] * np.exp(-X[:, 1:2] * t) + X[:, 2:3] - y
        return np.mean(R**2, axis=1), R

    return Problem(np.array([0.1, 0.1, -2.0]), np.array([5.0, 5.0, 2.0]), lambda X: residuals(X)[0], residuals,
                   names=("a", "b", "c"))  # fmt: skip


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_polish_is_scipys_least_squares_without_the_last_jacobian(seed):
    """The polish (lsq.polish: the ported trust region on forward differences) reaches scipy's least_squares' final
    point on the same residual and Jacobian, bit for bit, with D fewer evaluations: scipy's Jacobian at the point it
    stops at, which it does not use."""
    from scipy.optimize import least_squares

    problem = decaying(seed)
    lo, hi = problem.lower, problem.upper
    width = hi - lo
    run = Search(problem, np.random.default_rng(0), 10_000)
    x = lsq.polish(run, np.array([1.0, 0.5, 0.0]), tol=1e-10)
    count = [0]

    def residual(x):
        count[0] += 1
        return problem.residuals(x[None, :])[1][0]

    def jacobian(x):
        step = np.where(x + lsq.JACOBIAN_STEP * width <= hi, lsq.JACOBIAN_STEP * width, -lsq.JACOBIAN_STEP * width)
        count[0] += x.size
        R = problem.residuals(x[None, :] + np.diag(step))[1]
        R -= problem.residuals(x[None, :])[1][0][None, :]
        R /= step[:, None]
        return R.T

    ref = least_squares(residual, np.array([1.0, 0.5, 0.0]), jac=jacobian, bounds=(lo, hi), method="trf",
                        x_scale=width, xtol=1e-10, ftol=1e-10, gtol=1e-10)  # fmt: skip
    assert np.array_equal(x, ref.x)
    assert run.evaluations == count[0] - 3


def test_parallel_fits_come_back_in_the_candidates_order():
    """Longest first in the pool, the results in the candidates' order whatever the finishing order."""
    cands = [A.parameter_candidate(n, 1.0) for n in ("kf", "kr", "cf")] + [
        A.Candidate("slow", ("slow.a",), shape=("slow.s",), starts=({}, {}, {}), linear=False)
    ]  # fmt: skip
    assert max(cands, key=A.expected_seconds).effect == "slow"
    seen = []
    got = A.run_all(lambda c: c.effect, cands, None, seen.append)
    assert got == [c.effect for c in cands] and sorted(seen) == [1, 2, 3, 4]


def test_threads_1_fits_the_candidates_one_at_a_time_on_the_calling_thread(monkeypatch):
    """A long record's window fits its candidates one at a time (`threads=1`, the loop's choice: two fits at once were
    the 60 s diagnosis's peak memory): every fit runs on the caller's thread, in the candidates' order; with cores to
    spare and no limit they go to a pool."""
    import threading

    monkeypatch.setattr(A, "available_cores", lambda: 2)
    cands = [A.parameter_candidate(n, 1.0) for n in ("kf", "kr", "cf")]
    calls = []

    def one(c):
        calls.append((c.effect, threading.get_ident()))
        return c.effect

    assert A.run_all(one, cands, None, lambda _n: None, threads=1) == [c.effect for c in cands]
    assert calls == [(c.effect, threading.get_ident()) for c in cands]
    calls.clear()
    assert A.run_all(one, cands, None, lambda _n: None) == [c.effect for c in cands]
    assert all(ident != threading.get_ident() for _, ident in calls)


def test_fitted_basis_without_exact_sensitivities_falls_back_to_differences():
    """A linear twin whose problem has no `linearised` (a long record's has normal equations only; the four-post
    rig's README example raised TypeError here): the basis from forward differences, as with no twin."""
    rng = np.random.default_rng(5)
    A_, y = rng.standard_normal((100, 4)), rng.standard_normal(100)

    def residuals(X):
        R = np.atleast_2d(X) @ A_.T - y
        return np.mean(R**2, axis=1), R

    lo, hi = -np.ones(4), np.ones(4)
    problem = Problem(lo, hi, lambda X: residuals(X)[0], residuals, names=("a", "b", "c", "d"))
    free = np.ones(4, dtype=bool)  # all free: where the twin's exact sensitivities would be used
    got = fitted_basis(problem, np.zeros(4), free, Problem(lo, hi, problem.cost, residuals))
    want = np.linalg.svd(A_, full_matrices=False)[0]
    np.testing.assert_allclose(np.abs(got.T @ want), np.eye(4), atol=1e-6)  # the same span (signs aside)


def test_backlash_on_data_without_play_ends_at_its_rigid_corner_in_few_simulations():
    """Clean data (no play): backlash's fit heads for the rigid mount. Its contact stiffness is bounded below RK4's
    divergence (models/effects/backlash) and that corner is a start, so the fit ends there, at the bound, in a few
    trust-region steps (it had crept along the edge of divergence for 142 evaluations, 181 simulations with the
    screening of its starts), never below the declared model's J (LR 0)."""
    task, ref, keep = case()
    problem = masked(task.problem(ref), keep)
    declared = A.lsq_fit(problem, task.nominal, 600)
    cfg = prepare_config(load_config(BASE, NOISE))
    cand = A.candidate_specs(cfg, cfg.simulation.dt)["backlash"]
    aug = task.with_unknowns(list(cand.unknowns + cand.shape), limits={**cand.limits, **cand.shape_limits},
                             start=cand.start)  # fmt: skip
    counting, n = counted(masked(aug.problem(ref), keep))
    base = A.Fit(tuple(task.names), declared.x, declared.J, declared.evaluations)
    fit = A.candidate_fit(counting, base, aug.nominal[task.dim :], cand, 150, declared.J)
    names = list(counting.names)
    k = fit.x[names.index("backlash.k_contact")]
    assert k == pytest.approx(cand.shape_limits["backlash.k_contact"][1], rel=1e-6)  # at the bound, under the edge
    assert fit.x[names.index("backlash.gap_f")] == pytest.approx(cand.limits["backlash.gap_f"][0], rel=0.2)
    assert fit.J > declared.J and fit.evaluations <= 20 and n[0] <= 100
