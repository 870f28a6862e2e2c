"""Objectives and noise estimation against closed forms and the known noise of simulated data."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import BASE_CONFIG
from vehid_cli.config import load_config
from vehid_cli.core.streams import run_streams
from vehid_cli.identify.experiment import build_experiment
from vehid_cli.identify.objectives import Objective, objective_families
from vehid_cli.models.noise import add_noise, estimate_noise_sigma, noise_sigma, sigma_from_level


def fake_response(acc, disp):
    """Simulated channels by family, as Experiment.outputs gives them."""
    return {"acc": acc, "disp": disp}


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


def test_profiled_offsets_make_costs_blind_to_constant_offsets_and_equal_the_centred_fit():
    rng = np.random.default_rng(5)
    ref = rng.standard_normal((50, 3))
    sim = rng.standard_normal((2, 50, 3))
    offset = np.array([0.3, -2.0, 7.0])
    for name in ("wls", "f2"):
        plain = Objective(name, {"acc": ref}, {"acc": np.ones(3)}, offsets=True)
        shifted = Objective(name, {"acc": ref + offset}, {"acc": np.ones(3)}, offsets=True)
        np.testing.assert_allclose(plain.costs({"acc": sim}), shifted.costs({"acc": sim}), rtol=1e-12)
    # wls with the offsets profiled = the least-squares offset fitted explicitly (closed form: the mean error)
    obj = Objective("wls", {"acc": ref + offset}, {"acc": np.ones(3)}, offsets=True)
    best = (ref + offset - sim).mean(axis=1, keepdims=True)
    np.testing.assert_allclose(obj.costs({"acc": sim}), np.mean((ref + offset - sim - best) ** 2, axis=(1, 2)))


def test_observed_samples_only_enter_the_residuals():
    ref = np.arange(12.0).reshape(4, 3)
    sim = np.zeros((1, 4, 3))
    observed = np.ones((4, 3), dtype=bool)
    observed[1::2, 2] = False  # channel 3 sampled at half the rate
    obj = Objective("wls", {"acc": ref}, {"acc": np.ones(3)}, observed={"acc": observed})
    r = obj.residuals({"acc": sim})
    assert r.shape == (1, 10) and obj.size == 10
    np.testing.assert_array_equal(np.sort(r[0]), np.sort(ref[observed]))
    assert obj.costs({"acc": sim})[0] == pytest.approx(np.mean(ref[observed] ** 2))


@pytest.mark.parametrize("offsets", [False, True])
def test_residual_jacobian_is_the_residuals_response_to_the_outputs(offsets):
    """The residuals are affine in the model's outputs: moving the outputs along a parameter's sensitivities moves
    them by the residual Jacobian's column (to round-off), family by family, with and without profiled offsets."""
    rng = np.random.default_rng(7)
    n, D = 50, 3
    ref = {"acc": rng.standard_normal((n, 4)), "disp": rng.standard_normal((n, 3))}
    sigma = {"acc": rng.uniform(0.5, 2.0, 4), "disp": rng.uniform(0.5, 2.0, 3)}
    obj = Objective("wls", ref, sigma, offsets=offsets)
    out = {f: rng.standard_normal(v.shape) for f, v in ref.items()}
    big = rng.standard_normal((n, 9, D))  # the families' sensitivities as views of one array, like the car's
    sens = {"acc": big[:, :4], "disp": big[:, 4:7]}
    J = obj.residual_jacobian(sens)
    r0 = obj.residuals({f: v[None] for f, v in out.items()})[0]
    for j in range(D):
        moved = {f: (out[f] + sens[f][..., j])[None] for f in out}
        np.testing.assert_allclose(obj.residuals(moved)[0] - r0, J[:, j], rtol=0, atol=1e-12)
