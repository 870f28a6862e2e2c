"""Objectives and noise estimation against closed forms and the known noise of simulated data."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import BASE_CONFIG
from vehid_cli.config import load_config
from vehid_cli.core.streams import run_streams
from vehid_cli.identify.experiment import build_experiment
from vehid_cli.identify.objectives import Objective, mean_square, objective_families, sum_of_squares
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


@pytest.mark.parametrize("n", [5, 129, 16385, 16391, 100003, 960000])
@pytest.mark.parametrize("rows", [None, 1, 3])
def test_sum_of_squares_is_numpys_bit_for_bit(n, rows):
    """sum_of_squares and mean_square give np.sum(r**2, axis=-1) and np.mean(r**2, axis=-1) bit for bit (a
    pairwise sum split where NumPy splits it), on contiguous rows and on views of a larger array at any offset; the
    test fails if the squares' subtrees are cut anywhere else (e.g. at n // 2 unrounded)."""
    rng = np.random.default_rng(n)
    big = rng.standard_normal((4, n + 7)) * rng.uniform(0.01, 100.0, n + 7)
    views = [big[0, :n].copy(), big[1, 3 : n + 3]] if rows is None else [big[:rows, :n].copy(), big[1:, 5 : n + 5]]
    for r in views:
        np.testing.assert_array_equal(sum_of_squares(r), np.sum(r**2, axis=-1))
        with np.errstate(all="ignore"):
            np.testing.assert_array_equal(mean_square(r), np.mean(r**2, axis=-1))


@pytest.mark.parametrize("observed", [False, True])
def test_residuals_made_over_the_outputs_are_the_same_numbers(observed, monkeypatch):
    """costs_and_residuals with `overwrite` (the errors made in the simulation's arrays: here, as the exact
    sensitivities give them, strided column blocks of one array, gathered a few rows at a time) gives the costs and
    residuals of the plain call bit for bit, with profiled offsets and observed masks, and leaves the reference
    untouched; Eq. 8, which reads the outputs again, does not overwrite them."""
    from vehid_cli.identify import objectives

    monkeypatch.setattr(objectives, "GATHER_ROWS", 64)  # several blocks of the 500 samples, the last one short
    rng = np.random.default_rng(3)
    ref = {"acc": rng.standard_normal((500, 3)), "disp": rng.standard_normal((500, 2))}
    mask = {f: rng.uniform(size=v.shape) > 0.3 for f, v in ref.items()} if observed else None
    sigma = {f: rng.uniform(0.5, 2.0, v.shape[1]) for f, v in ref.items()}
    Y = np.concatenate([ref["acc"], ref["disp"]], axis=1) + 0.1 * rng.standard_normal((500, 5)) + 0.3
    sim = {"acc": Y[:, :3], "disp": Y[:, 3:]}  # strided views, as Experiment.exact_sensitivities returns them
    before = {f: v.copy() for f, v in ref.items()}
    wls = Objective("wls", ref, sigma, observed=mask, offsets=True)
    want = wls.costs_and_residuals({f: v[None].copy() for f, v in sim.items()})
    scratch = Y.copy()
    got = wls.costs_and_residuals({"acc": scratch[None, :, :3], "disp": scratch[None, :, 3:]}, overwrite=True)
    np.testing.assert_array_equal(got[0], want[0])
    np.testing.assert_array_equal(got[1], want[1])
    assert not np.array_equal(scratch, Y)  # written over: no copy of the record made
    assert all(np.array_equal(ref[f], before[f]) for f in ref)
    f1 = Objective("f1", {"disp": ref["disp"]}, {"disp": sigma["disp"]}, observed=None, offsets=False)
    kept = {"disp": sim["disp"][None].copy()}
    costs = f1.costs_and_residuals(kept, overwrite=True)[0]
    np.testing.assert_array_equal(costs, f1.costs({"disp": sim["disp"][None]}))
    np.testing.assert_array_equal(kept["disp"][0], sim["disp"])
