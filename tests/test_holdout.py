"""diagnose/holdout.py: the masked problem's residuals and costs without a second (P, R) array."""

from __future__ import annotations

import numpy as np
import pytest

from vehid_cli.diagnose import holdout
from vehid_cli.diagnose.holdout import holdout_blocks, kept_in_place, masked
from vehid_cli.identify.objectives import mean_square
from vehid_cli.optimizers.base import Problem


@pytest.mark.parametrize("P, R", [(1, 1000), (13, 4801), (4, 12345)])
def test_kept_entries_and_costs_equal_numpy_indexing(P, R):
    """kept_in_place gives what r[:, keep] gives, bit for bit, and mean_square what np.mean(r**2, axis=1) gives to
    round-off (r[:, keep] is in Fortran order: NumPy sums its rows in another order than a C-ordered row's)."""
    rng = np.random.default_rng(P)
    r = rng.standard_normal((P, R)) * rng.uniform(0.1, 10.0, R)
    keep = ~np.repeat(holdout_blocks(R // 8 + 1), 8)[:R]
    want = r[:, keep]
    got = kept_in_place(r.copy(), np.flatnonzero(keep))
    np.testing.assert_array_equal(got, want)
    np.testing.assert_allclose(mean_square(got), np.mean(want**2, axis=1), rtol=1e-13, atol=0)  # want: F order


def test_masked_problem_residuals(monkeypatch):
    """The masked problem's residuals are the kept entries of the problem's, its costs their mean square."""
    rng = np.random.default_rng(0)
    A = rng.standard_normal((600, 2))

    def cr(X):
        r = X @ A.T - 1.0  # fresh each call, as every problem's residuals are
        return np.mean(r**2, axis=1), r

    problem = Problem(np.zeros(2), np.ones(2), lambda X: cr(X)[0], cr, names=("a", "b"))
    keep = rng.uniform(size=600) > 0.3
    X = rng.uniform(size=(5, 2))
    costs, r = masked(problem, keep).residuals(X)  # short: NumPy's own expressions, bit for bit
    np.testing.assert_array_equal(r, cr(X)[1][:, keep])
    np.testing.assert_array_equal(costs, np.mean(cr(X)[1][:, keep] ** 2, axis=1))
    monkeypatch.setattr(holdout, "IN_PLACE_BYTES", 0)  # as a long record's: in place, to round-off
    costs, r = masked(problem, keep).residuals(X)
    np.testing.assert_array_equal(r, cr(X)[1][:, keep])
    np.testing.assert_allclose(costs, np.mean(cr(X)[1][:, keep] ** 2, axis=1), rtol=1e-13, atol=0)


@pytest.mark.parametrize("offsets", [False, True])
def test_a_long_records_batch_is_made_at_its_kept_entries_only_with_the_same_numbers(monkeypatch, offsets):
    """A task's problem masked by the held-out blocks: a batch above IN_PLACE_BYTES (a long record's) is simulated
    and weighted at the kept entries only (`Problem.kept`, task.kept_residuals; no (P, R) array), with the costs and
    residuals of the whole vectors' kept entries bit for bit, chunked or not, observed masks and offsets included."""
    import dataclasses

    from tests.conftest import BASE_CONFIG
    from vehid_cli.config import load_config
    from vehid_cli.identify.experiment import Experiment
    from vehid_cli.identify.task import build_task

    sets = ["identify.objective=wls", "noise.level=0.03", "simulation.duration=1", "identify.truth=config"]
    task = dataclasses.replace(build_task(load_config(BASE_CONFIG, sets)), offsets=offsets)
    ref = task.reference(0)
    if offsets:  # a channel sampled every other row: observed masks, the objective's own entries
        observed = {f: np.ones(v.shape, dtype=bool) for f, v in ref.items()}
        observed["acc"][1::2, 2] = False
        task = dataclasses.replace(task, observed=observed)
    problem = task.problem(ref)
    assert problem.kept is not None
    R = problem.residuals(task.nominal[None, :])[1].shape[1]
    keep = ~np.resize(holdout_blocks(R // 2), R)
    X = task.nominal * np.random.default_rng(6).uniform(0.97, 1.03, size=(5, task.dim))
    monkeypatch.setattr(holdout, "IN_PLACE_BYTES", 0)
    for chunk in (2, 8):
        monkeypatch.setattr(Experiment, "cars_per_chunk", property(lambda self, c=chunk: c))
        new = masked(problem, keep).residuals(X)
        old = masked(dataclasses.replace(problem, kept=None), keep).residuals(X)
        assert new[1].flags.c_contiguous and new[1].shape == (5, keep.sum())
        assert np.array_equal(new[1], old[1]) and np.array_equal(new[0], old[0])


@pytest.mark.parametrize("offsets", [False, True])
def test_a_long_records_normal_equations_are_masked_to_the_kept_samples(monkeypatch, offsets):
    """The masked problem's normal equations (a long record's, summed block by block over the kept samples) are
    J'J and J'r of the exact Jacobian's kept rows and its cost their residuals' mean square; with profiled offsets
    (means over every observed sample, not these sums) there are none, and the fit falls back to differences."""
    import dataclasses

    from tests.conftest import BASE_CONFIG
    from vehid_cli.config import load_config
    from vehid_cli.identify.task import build_task
    from vehid_cli.optimizers import lsq

    sets = ["identify.objective=wls", "noise.level=0.03", "simulation.duration=5", "simulation.integrator=exact",
            "identify.truth=config"]  # fmt: skip
    task = dataclasses.replace(build_task(load_config(BASE_CONFIG, sets)), offsets=offsets).with_unknowns(("kf", "cr"))
    ref = task.reference(0)
    x = task.nominal * np.random.default_rng(2).uniform(0.95, 1.05, task.dim)
    _, r, jac = task.problem(ref).linearised(x)  # a short record's: the whole Jacobian
    keep = ~np.resize(holdout_blocks(r.size // 4), r.size)
    monkeypatch.setattr(lsq, "LONG_JACOBIAN_BYTES", 1024)  # the same record taken as long: its sums, no Jacobian
    long = task.problem(ref)
    assert long.linearised is None and long.normal is not None
    got = masked(long, keep).normal(x)
    if offsets:
        assert got is None
        return
    cost, rk, H, g = got
    J, rr = jac[keep], r[keep]
    np.testing.assert_array_equal(rk, rr)
    assert cost == pytest.approx(np.mean(rr**2), rel=1e-12)
    scale = np.sqrt(np.diag(J.T @ J))
    np.testing.assert_allclose(H / np.outer(scale, scale), (J.T @ J) / np.outer(scale, scale), atol=1e-10)
    np.testing.assert_allclose(g / scale, (J.T @ rr) / scale, atol=1e-10 * np.linalg.norm(rr))
    assert not np.allclose(H, jac.T @ jac, rtol=1e-3)  # the held-out rows are left out (the test can fail)
