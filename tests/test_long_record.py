"""A long record's fit within bounded memory (issue 26): the compressed least squares and the chunked residuals.

The compressed fit (optimizers/compressed.py) must take the same steps as the trust region on the full residual
(to round-off), hold far less than it does, and the residuals of a batch of cars simulated a chunk at a time
must be the unchunked ones bit for bit.
"""

from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

from examples.make_rig_runs import write_rig_run
from tests.conftest import ROOT
from vehid_cli.config import load_config
from vehid_cli.identify.crlb import information
from vehid_cli.identify.experiment import Experiment
from vehid_cli.identify.task import information_by_parameter
from vehid_cli.models.faults import delay
from vehid_cli.optimizers import get_optimizer, lsq
from vehid_cli.optimizers.base import Problem
from vehid_cli.optimizers.compressed import compress
from vehid_cli.systems import build_system

RIG = ROOT / "configs" / "examples" / "four_post_rig.yaml"


def damped_sine(n: int, seed: int = 5):
    """A nonlinear least-squares problem with a long residual: y = a exp(-b t) sin(w t + p) + c t + d, noisy, (n,)
    samples; returns (problem, truth)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 10.0, n)
    truth = np.array([1.5, 0.3, 2.0, 0.4, 0.05, -0.2])

    def model(X):
        a, b, w, p, c, d = (X[:, j, None] for j in range(6))
        return a * np.exp(-b * t) * np.sin(w * t + p) + c * t + d

    y = model(truth[None])[0] + 0.05 * rng.standard_normal(n)

    def residuals(X):
        X = np.atleast_2d(X)
        r, cost = np.empty((len(X), n)), np.empty(len(X))
        for i, x in enumerate(X):  # a candidate at a time: the problem holds (P, n) once, as a system's does
            r[i] = (y - model(x[None])[0]) / 0.05
            cost[i] = np.mean(r[i] ** 2)
        return cost, r

    lo, hi = truth - 0.3 * np.abs(truth) - 0.05, truth + 0.3 * np.abs(truth) + 0.05
    return Problem(lo, hi, lambda X: residuals(X)[0], residuals), truth


def fit(problem: Problem, limit: int, monkeypatch, seed: int = 3):
    """The lsq fit with Jacobians above `limit` bytes fitted compressed."""
    monkeypatch.setattr(lsq, "LONG_JACOBIAN_BYTES", limit)
    return get_optimizer("lsq").minimize(problem, np.random.default_rng(seed), budget=400)


@pytest.mark.parametrize("collinear", [1.0, 1e-6, 1e-12, 0.0])
def test_compress_keeps_the_normal_equations_and_the_residual_norm_whatever_the_block(collinear):
    """Against the R of NumPy's Householder QR of the whole [J r]: columns of scales 1e-4 to 1e4, two of them nearly
    (or exactly) parallel, which takes the CholeskyQR2 to its Householder fallback."""
    rng = np.random.default_rng(0)
    jt, r = rng.standard_normal((5, 1003)) * np.logspace(-4, 4, 5)[:, None], rng.standard_normal(1003)
    jt[3] = jt[2] * 3.0 + collinear * jt[3]
    whole = np.linalg.qr(np.column_stack([jt.T, r]), mode="r")
    gram, cross = whole[:5, :5].T @ whole[:5, :5], whole[:5, :5].T @ whole[:5, 5]
    for block in (1, 7, 256, 5000):
        rj, z, rho = compress(jt, r, block)
        np.testing.assert_allclose(rj.T @ rj, gram, rtol=1e-12, atol=1e-12 * np.abs(gram).max())
        np.testing.assert_allclose(rj.T @ z, cross, rtol=1e-12, atol=1e-12 * np.abs(cross).max())
        np.testing.assert_allclose(z @ z + rho**2, r @ r, rtol=1e-13)
        if collinear >= 1e-6:  # rank-deficient J: which part of r its QR calls rho is round-off's choice
            np.testing.assert_allclose(rho, abs(whole[5, 5]), rtol=1e-9)


@pytest.mark.parametrize("seed", range(3))
def test_the_compressed_fit_takes_the_full_fits_steps(seed, monkeypatch):
    """The same estimate (to round-off) and the same number of evaluations as the trust region on the full residual."""
    problem, truth = damped_sine(4000, seed)
    full = fit(problem, 2**62, monkeypatch, seed)
    small = fit(problem, 0, monkeypatch, seed)
    assert small.evaluations == full.evaluations
    np.testing.assert_allclose(small.x, full.x, rtol=1e-9)
    np.testing.assert_allclose(small.cost, full.cost, rtol=1e-12)
    assert np.all(np.abs(full.x - truth) < 0.05 * np.abs(truth) + 0.01)  # and it is a fit, not two equal failures


def traced_peak(problem: Problem, limit: int, monkeypatch) -> int:
    tracemalloc.start()
    try:
        fit(problem, limit, monkeypatch)
        return tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()


def test_the_compressed_fit_holds_the_jacobian_once(monkeypatch):
    """Peak traced memory of a fit over 200 000 residuals: the compressed one within the Jacobian, its residuals and
    the problem's temporaries (its result, one Jacobian, and a candidate's model: half of one): within two
    Jacobians; the full trust region's beyond four (its copies: the check can fail)."""
    n = 200_000
    problem, _ = damped_sine(n)
    jacobian = 6 * n * 8
    compressed = traced_peak(problem, 0, monkeypatch)
    full = traced_peak(problem, 2**62, monkeypatch)
    assert compressed < 2 * jacobian, (compressed / jacobian, full / jacobian)
    assert full > 4 * jacobian, (compressed / jacobian, full / jacobian)


@pytest.fixture(scope="module")
def rig_system(tmp_path_factory):
    run = write_rig_run(RIG, tmp_path_factory.mktemp("long") / "run.mf4", 7, ["simulation.duration=3"])
    return build_system(load_config(RIG, ["simulation.duration=3", "identify.truth=config"]), run)


def test_residuals_a_chunk_of_cars_at_a_time_are_the_unchunked_ones(rig_system, monkeypatch):
    system = rig_system
    rng = np.random.default_rng(1)
    box = system.box
    X = box.lower + (box.upper - box.lower) * rng.random((9, box.lower.size))
    whole = system.problem(system.reference(0)).residuals(X)
    for chunk in (1, 2, 4):  # chunks of 2, 2, 2, 3 cars (no single car: see chunked_residuals); 4, 5
        monkeypatch.setattr(Experiment, "cars_per_chunk", property(lambda self, c=chunk: c))
        chunked = system.problem(system.reference(0)).residuals(X)
        np.testing.assert_array_equal(chunked[0], whole[0])
        np.testing.assert_array_equal(chunked[1], whole[1])


def test_a_record_fitted_compressed_gives_the_full_fit(rig_system, monkeypatch):
    """The rig's 3 s record identified with every Jacobian compressed: the estimate of the full path to round-off.
    The last steps of a converged fit change the cost by round-off, so where the two stop may differ by a step."""
    monkeypatch.setattr(lsq, "LONG_JACOBIAN_BYTES", 2**62)
    full = rig_system.identify_run(0)
    monkeypatch.setattr(lsq, "LONG_JACOBIAN_BYTES", 0)
    small = rig_system.identify_run(0)
    assert abs(small.evaluations - full.evaluations) <= len(full.estimate) + 1
    np.testing.assert_allclose(small.estimate, full.estimate, rtol=1e-9)
    np.testing.assert_allclose(small.chi2, full.chi2, rtol=1e-10)


def test_the_information_a_parameter_at_a_time_is_the_batched_one(rig_system, monkeypatch):
    """information_by_parameter (a long record's) against crlb.information (every perturbed car in one batch), at a
    point off the configured car (the held unknowns must be held there, not at their configured values); both by
    central differences (exact sensitivities, which a long record uses when they apply, are tested against central
    differences in test_sensitivity.py)."""
    monkeypatch.setattr(Experiment, "exact_sensitivities", lambda self, names, values: None)
    task = rig_system.task
    at = task.nominal * np.linspace(0.95, 1.05, task.nominal.size)
    batched = information(task.experiment, task.names, at, task.sigma, task.observed, task.offsets)
    blocked = information_by_parameter(task.experiment, task.names, at, task.sigma, task.observed, task.offsets)
    np.testing.assert_allclose(blocked, batched, rtol=1e-10, atol=1e-12 * np.abs(batched).max())
    assert np.all(np.diag(batched) > 0)


class _Forgetful(dict):
    def __setitem__(self, key, value) -> None:
        pass


def test_the_checks_find_the_same_with_the_lags_remembered(rig_system, monkeypatch):
    """delay.lag_of remembers each channel's lag (the checks asked for every channel's from every other channel's
    check): the findings are those of recomputing every one."""
    remembered = rig_system.checks().to_json()
    monkeypatch.setattr(delay, "_LAGS", _Forgetful())
    assert rig_system.checks().to_json() == remembered
