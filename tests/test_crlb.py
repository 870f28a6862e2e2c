"""The Cramér–Rao bound against a Monte-Carlo of real maximum-likelihood fits, and identifiability flags."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import BASE_CONFIG
from vehid_cli.config import load_config
from vehid_cli.core.streams import run_streams
from vehid_cli.identify.task import build_task
from vehid_cli.optimizers import get_optimizer

SMALL = ["simulation.duration=1.5", "simulation.dt=0.002", "sensors=acc", "identify.objective=wls", "noise.level=0.2"]


def test_bound_matches_monte_carlo_of_ml_fits():
    """100 noise realisations, each fitted by least squares on the Gaussian likelihood from the truth: the spread
    of the estimates is the bound (an efficient estimator), within the Monte-Carlo error of ~7 %."""
    cfg = load_config(BASE_CONFIG, SMALL + ["identify.unknowns=[m, Iy]", "identify.runs=100"])
    task = build_task(cfg)
    bound = task.bound()
    lsq = get_optimizer("lsq")
    estimates = []
    for run in range(100):
        result = lsq.minimize(
            task.problem(task.reference(run)), run_streams(0, run).optimizer, budget=80, x0=task.truth
        )
        estimates.append(result.x)
    re = 100 * (np.array(estimates) / task.truth - 1)
    ratio = re.std(axis=0, ddof=1) / bound.re_sd_percent
    np.testing.assert_allclose(ratio, 1.0, atol=0.2)
    assert np.all(np.abs(re.mean(axis=0)) < 3 * bound.re_sd_percent / np.sqrt(100))  # unbiased


def test_bound_scales_with_noise_level():
    b1 = build_task(load_config(BASE_CONFIG, SMALL)).bound()
    b2 = build_task(load_config(BASE_CONFIG, SMALL + ["noise.level=0.1"])).bound()
    np.testing.assert_allclose(b1.re_sd_percent / b2.re_sd_percent, 2.0, rtol=1e-6)
    assert all(b1.identifiable)


def test_unidentifiable_parameter_is_flagged():
    """Without the anti-roll bar and with equal bump heights left and right, nothing excites roll: Ix is invisible."""
    cfg = load_config(
        BASE_CONFIG,
        SMALL + ["road.bump.heights=[0.05, 0.05, 0.05, 0.05]", "identify.unknowns=[m, Ix, Iy]"],
    )
    bound = build_task(cfg).bound()
    assert bound.unidentifiable() == ["Ix"]
    assert bound.re_sd_percent[0] < 1 and bound.re_sd_percent[2] < 1


@pytest.mark.parametrize("name", ["m", "Iy"])
def test_sensitivities_are_converged(name):
    """Halving the finite-difference step leaves the bound unchanged."""
    from vehid_cli.identify.crlb import cramer_rao

    task = build_task(load_config(BASE_CONFIG, SMALL + [f"identify.unknowns=[{name}]"]))
    a = cramer_rao(task.experiment, task.names, task.truth, task.sigma, rel_step=1e-5)
    b = cramer_rao(task.experiment, task.names, task.truth, task.sigma, rel_step=5e-6)
    np.testing.assert_allclose(a.re_sd_percent, b.re_sd_percent, rtol=1e-4)
