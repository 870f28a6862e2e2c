"""identify/forward.py: a forward-difference Jacobian's Gram matrix summed over a record in time blocks equals the
whole Jacobian's J'J, J'r, r'r (held-out entries, observed masks and profiled offsets included), without the (D, R)
array."""

from __future__ import annotations

import dataclasses
import tracemalloc

import numpy as np
import pytest

from vehid_cli.diagnose.holdout import holdout_blocks, masked
from vehid_cli.identify.experiment import Experiment
from vehid_cli.identify.forward import forward_gram
from vehid_cli.optimizers.compressed import compress, compress_gram


def _task(offsets: bool, seconds: float):
    from tests.conftest import BASE_CONFIG
    from vehid_cli.config import load_config
    from vehid_cli.identify.task import build_task

    sets = ["identify.objective=wls", "noise.level=0.03", f"simulation.duration={seconds}",
            "simulation.integrator=rk4", "identify.truth=config"]  # fmt: skip
    task = dataclasses.replace(build_task(load_config(BASE_CONFIG, sets)), offsets=offsets)
    task = task.with_unknowns(("kf", "kr", "cf", "cr"))  # D = 9, as a diagnosis's re-fit
    ref = task.reference(0)
    if offsets:  # a channel sampled every other row: observed masks, the objective's own entries
        observed = {f: np.ones(v.shape, dtype=bool) for f, v in ref.items()}
        observed["acc"][1::2, 2] = False
        task = dataclasses.replace(task, observed=observed)
    return task, ref


def _points(task) -> tuple[np.ndarray, np.ndarray]:
    x = task.nominal * np.random.default_rng(3).uniform(0.98, 1.02, task.dim)
    step = 1e-6 * x * np.where(np.arange(task.dim) % 2, 1.0, -1.0)
    return np.vstack([x[None, :], x[None, :] + np.diag(step)]), step


def _relative(G: np.ndarray, want: np.ndarray) -> float:
    """The largest difference of G from `want`, entry by entry relative to sqrt(want_ii want_jj)."""
    d = np.sqrt(np.diag(want))
    return float(np.max(np.abs(G - want) / np.outer(d, d)))


@pytest.mark.parametrize("offsets", [False, True])
def test_blocked_sums_equal_the_whole_jacobians(monkeypatch, offsets):
    """On a record of three blocks, with a hold-out split (and observed masks and profiled offsets): the Gram matrix
    of [J r] summed block by block equals the one of the whole residual vectors' forward differences at the kept
    entries, to 1e-9 of each entry's scale, and its compressed pair gives the same J'J, J'r, r'r as `compress`'s;
    through the masked problem's hook (a long record's) the same, with the cars split over threads or not."""
    task, ref = _task(offsets, 5)
    assert task.experiment.t.size > 2 * 2048  # several blocks
    problem = task.problem(ref)
    X, step = _points(task)
    _, R = problem.residuals(X)
    keep = ~np.resize(holdout_blocks(R.shape[1] // 2), R.shape[1])
    R = R[:, keep]
    J = (R[1:] - R[0]) / step[:, None]
    A = np.vstack([J, R[:1]])
    want = A @ A.T
    rows = np.flatnonzero(keep)
    G = forward_gram(task.experiment, task.objective(ref), {n: X[:, j] for j, n in enumerate(task.names)}, step, rows)
    assert _relative(G, want) < 1e-9
    rj, z, rho = compress_gram(G)
    rj0, z0, rho0 = compress(J, R[0])
    np.testing.assert_allclose(rj.T @ rj, rj0.T @ rj0, rtol=1e-8, atol=1e-9 * np.max(np.abs(rj0.T @ rj0)))
    np.testing.assert_allclose(rj.T @ z, rj0.T @ z0, rtol=1e-8, atol=1e-9 * np.max(np.abs(rj0.T @ z0)))
    assert abs(z @ z + rho**2 - (z0 @ z0 + rho0**2)) < 1e-10 * (z0 @ z0 + rho0**2)
    assert problem.gram(X, step, rows) is None  # a short record: its Jacobian is held, today's path
    monkeypatch.setattr(Experiment, "long", property(lambda self: True))
    monkeypatch.setattr(Experiment, "blocked", lambda self, values=None: True)
    assert _relative(masked(problem, keep).gram(X, step, None), want) < 1e-9
    monkeypatch.setattr("vehid_cli.identify.forward.available_cores", lambda: 1)
    assert _relative(masked(problem, keep).gram(X, step, None), want) < 1e-9


def test_blocked_sums_hold_no_record_sized_jacobian():
    """The sums' traced peak does not grow with the record as the (D, R_kept) Jacobian they replace does: from 10 to
    40 s (5 to 20 blocks) it grows by less than a quarter of the Jacobian's growth, where the residuals of the D + 1
    cars (the usual way to form J) grow by more than all of it."""

    def traced_peak(run, *args) -> int:
        tracemalloc.start()
        try:
            run(*args)
            return tracemalloc.get_traced_memory()[1]
        finally:
            tracemalloc.stop()

    peaks = []
    for seconds in (10, 40):
        task, ref = _task(True, seconds)
        problem = task.problem(ref)
        X, step = _points(task)
        keep = ~np.resize(holdout_blocks(task.residual_samples // 2), task.residual_samples)
        rows = np.flatnonzero(keep)
        objective = task.objective(ref)
        values = {n: X[:, j] for j, n in enumerate(task.names)}
        forward_gram(task.experiment, objective, values, step, rows)  # compiled, cached
        blocked = traced_peak(forward_gram, task.experiment, objective, values, step, rows)
        whole = traced_peak(problem.kept, X, rows)
        peaks.append((task.dim * rows.size * 8, blocked, whole))
    (j10, b10, w10), (j40, b40, w40) = peaks
    assert w40 - w10 > j40 - j10  # the check can fail: the usual way is caught by it
    assert b40 - b10 < (j40 - j10) / 4
