"""Objectives and noise estimation against closed forms and the known noise of simulated data."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import BASE_CONFIG
from vehid_cli.config import load_config
from vehid_cli.experiment import build_experiment, run_streams
from vehid_cli.noise import add_noise, estimate_noise_sigma, noise_sigma, sigma_from_level
from vehid_cli.objectives import Objective, objective_families
from vehid_cli.sim.linear import Response


def fake_response(acc, disp):
    n = acc.shape[-2]
    z = np.zeros(acc.shape[:-1] + (7,))
    return Response(t=np.arange(n), q=z, qd=z, qdd=z, disp=disp, acc=acc)


def test_f2_is_eq8_sum_of_norms_over_sum_of_norms():
    ref = np.array([[3.0, 0, 1, 1], [4.0, 1, 1, 1]])  # two samples, four channels
    sim = np.array([[0.0, 0, 1, 1], [0.0, 1, 1, -1]])
    obj = Objective("f2", {"acc": ref}, {"acc": np.ones(4)})
    expected = (5.0 + 0 + 0 + 2.0) / (5.0 + 1 + np.sqrt(2) + np.sqrt(2))
    assert obj.costs(fake_response(sim[None], sim[None]))[0] == pytest.approx(expected)
    assert obj.costs(fake_response(ref[None], ref[None]))[0] == 0.0


def test_families_of_each_objective():
    assert objective_families("f1", "both") == ("disp",)
    assert objective_families("f2", "both") == ("acc",)
    assert objective_families("wls", "both") == ("acc", "disp")
    assert objective_families("wls", "disp") == ("disp",)


@pytest.fixture(scope="module")
def clean_paper_response():
    return build_experiment(load_config(BASE_CONFIG)).simulate()


def test_wls_is_one_per_sample_at_the_truth(clean_paper_response):
    clean = clean_paper_response
    rng = run_streams(3, 0).noise
    noisy = add_noise(clean.acc, 0.1, rng)
    obj = Objective("wls", {"acc": noisy}, {"acc": noise_sigma(clean.acc, 0.1)})
    chi2 = obj.costs(fake_response(clean.acc[None], clean.disp[None]))[0]
    assert chi2 == pytest.approx(1.0, abs=4 * np.sqrt(2 / noisy.size))  # chi² of 12000 samples: sd sqrt(2/n)


@pytest.mark.parametrize("family", ["acc", "disp"])
@pytest.mark.parametrize("level", [0.05, 0.2])
def test_noise_estimated_from_data_alone(clean_paper_response, family, level):
    clean = getattr(clean_paper_response, family)
    noisy = add_noise(clean, level, np.random.default_rng(11))
    true_sigma = noise_sigma(clean, level)
    np.testing.assert_allclose(estimate_noise_sigma(noisy), true_sigma, rtol=0.08)
    np.testing.assert_allclose(sigma_from_level(noisy, level), true_sigma, rtol=0.03)
