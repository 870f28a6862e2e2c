"""Issue 11, acceptance 2 and 3: the loop on car runs made by an independent simulator (tests/independent_sim.py:
Newton per body through scipy's LSODA, not vehid's code), 5 % noise, the paper's bump.

The cases of the issue's table (mis-set known parameters, Bouc-Wen loops wider and later-yielding than the
library's default, tyre damping with hysteresis) must be named as in acceptance 1; strut forces outside the
library (a square-root damper, a bump stop with a dead band) must give "incomplete" with the unexplained
force estimated, never "found".
"""

from __future__ import annotations

import pytest

from tests import independent_sim as S
from tests.conftest import BASE_CONFIG
from tests.test_diagnose_effects import DIAGNOSE, assert_named
from vehid_cli.config import load_config
from vehid_cli.systems.vehicle.diagnosis import diagnose


def run(tmp_path, params=None, effects=None, seed=1):
    path = tmp_path / "independent.csv"
    S.write_run(path, S.simulate(params, effects), noise_level=0.05, seed=seed)
    return diagnose(load_config(BASE_CONFIG, DIAGNOSE), path, analyse_residuals=False)


def test_wide_hysteresis_loop_from_another_simulator(tmp_path):
    d = run(tmp_path, effects={"hysteresis": {"beta": 1e4, "gamma": 1e4}}, seed=22)
    assert_named(d, ["hysteresis"])


@pytest.mark.slow
@pytest.mark.parametrize(
    ("params", "effects", "expected"),
    [
        ({"kf": 54000, "cr": 2975}, None, ["parameter:kf", "parameter:cr"]),
        (None, {"hysteresis": {"beta": 3e3, "gamma": 3e3, "alpha_f": 2.5e4, "alpha_r": 2.5e4}}, ["hysteresis"]),
        (None, {"hysteresis": {"beta": 2e4, "gamma": 2e4}, "tyre_damping": None}, ["hysteresis", "tyre_damping"]),
        ({"kR": 60000}, None, ["parameter:kR"]),
        (None, {"coulomb_friction": {"Fc_f": 120, "Fc_r": 180, "v_eps": 0.02}}, ["coulomb_friction"]),
        (None, {"progressive_spring": {"k3_f": 2e7, "k3_r": 3e7}}, ["progressive_spring"]),
    ],
    ids=["kf-cr", "late-yield", "tyre+hysteresis", "kR", "friction", "progressive"],
)
def test_the_issue_table_from_another_simulator(tmp_path, params, effects, expected):
    assert_named(run(tmp_path, params, effects, seed=23), expected)


@pytest.mark.slow
def test_clean_run_from_another_simulator_is_adequate(tmp_path):
    d = run(tmp_path, seed=27)
    assert d.selected == ()
    assert d.verdict.startswith("adequate")


@pytest.mark.slow
@pytest.mark.parametrize(
    ("effects", "shape", "pointed"),
    [
        ({"sqrt_damper": None}, "velocity", {"parameter:cf", "parameter:cr", "coulomb_friction"}),
        ({"bump_stop": {"gap_f": 0.015, "gap_r": 0.015}}, "deflection", {"backlash", "progressive_spring"}),
    ],
    ids=["sqrt-damper", "bump-stop"],
)
def test_a_force_outside_the_library_is_incomplete_not_found(tmp_path, effects, shape, pointed):
    d = run(tmp_path, effects=effects, seed=25)
    assert d.verdict.startswith("incomplete"), d.verdict
    assert not d.verdict.startswith("found")
    assert d.unexplained is not None and d.unexplained.significant
    assert d.unexplained.to_json()["acts_on"]["variable"] == shape
    assert pointed <= set(d.unexplained.points_to)  # the library's terms of its shape: a damping law, a dead band


def assert_honest(d, truth):
    """Every estimate of the final model whose truth is known (the declared unknowns and the freed known parameters)
    within 3.3 standard errors of it (its 95 % half-width / 1.96)."""
    for n, x, ci in zip(d.after.names, d.after.x, d.after.ci, strict=True):
        if n in truth:
            z = abs(x - truth[n]) / (ci / 1.96)
            assert z <= 3.3, (n, x, truth[n], ci, z)


@pytest.mark.slow
@pytest.mark.parametrize(
    ("off", "seed"),
    [
        ({"ktr": 0.9, "kR": 1.2}, 23),
        ({"ktr": 0.9, "kR": 1.2, "mr": 1.15}, 23),
        ({"kf": 1.15, "cr": 0.85, "ktf": 0.9}, 24),
    ],
    ids=["ktr-kR", "ktr-kR-mr", "kf-cr-ktf"],
)
def test_several_misset_known_parameters_reach_the_oracle_with_honest_intervals(tmp_path, off, seed):
    """Issue 25, acceptance 2: two or three known parameters off. A second one hardly shows in J once the first is
    freed (the residual is at the noise) but biases the unknowns: the loop still tests the known parameters, names
    each, and the final joint polish reaches the bound (NRE <= 1.5x the bound, <= 1/10 of before), every interval
    (from the joint covariance of the unknowns and the freed parameters) holding the truth."""
    params = {n: S.PAPER_CAR[n] * f for n, f in off.items()}
    d = run(tmp_path, params, seed=seed)
    assert set(d.selected) == {f"parameter:{n}" for n in off}, (d.selected, d.notes)
    assert d.verdict.startswith("found"), d.verdict
    assert d.after.nre_percent <= 1.5 * d.after.nre_bound_percent, (d.after.nre_percent, d.after.nre_bound_percent)
    assert d.after.nre_percent * 10 <= d.before.nre_percent
    assert_honest(d, {**{n: S.PAPER_CAR[n] for n in ("m", "Ix", "Iy", "a1", "b1")}, **params})


def assert_never_found_off(d, truth):
    """Issue 25, acceptance 1: "incomplete" with the law shown (the non-parametric force in the JSON; where library
    terms imitate it, the widened interval holding the model-based one, and the truth when they imitate it to the
    noise: above it neither explanation holds the law, and the spread between them need not bound the bias), or a
    claim (or "adequate") whose declared unknowns are within 3.3 standard errors of the truth; never "found" with
    them off."""
    if not d.verdict.startswith("incomplete"):
        assert d.verdict.startswith(("found", "adequate")), d.verdict
        assert_honest(d, truth)
        return
    assert d.unexplained is not None and d.unexplained.significant, d.verdict
    out = d.to_json()
    assert out["unexplained"] is not None
    if d.imitation:  # both intervals reported, the widened ones marked
        assert "library terms imitate a law they do not contain" in d.verdict
        mu = out["model_uncertainty"]
        assert set(mu["ci95_model_uncertainty"]) == set(truth)
        assert out["after"]["ci95_model_uncertainty"] == mu["ci95_model_uncertainty"]
        for n, (lo, hi) in mu["ci95_model_uncertainty"].items():
            assert lo <= out["after"]["ci95"][n][0] and hi >= out["after"]["ci95"][n][1]
            assert d.at_noise is False or lo <= truth[n] <= hi, (n, lo, hi, truth[n])


@pytest.mark.slow
@pytest.mark.parametrize(
    ("effects", "seed"),
    [
        ({"sqrt_damper": {"c_sqrt_f": 300.0, "c_sqrt_r": 400.0}}, 31),
        ({"quadratic_damper": None}, 32),
        ({"digressive_damper": None}, 33),
        ({"stribeck_friction": None}, 34),
        ({"progressive_tyre": None}, 35),
    ],
    ids=["weak-sqrt-damper", "quadratic-damper", "digressive-damper", "stribeck-friction", "progressive-tyre"],
)
def test_a_law_outside_the_library_is_never_found_with_unknowns_off(tmp_path, effects, seed):
    """Issue 25, acceptance 1, over kinds of laws outside the library (tests/independent_sim.OUTSIDE_LIBRARY): library
    terms can imitate them to the noise (a weak square-root damper: Coulomb friction and both dampers), bias the
    unknowns, or leave the residual above the noise."""
    d = run(tmp_path, effects=effects, seed=seed)
    assert_never_found_off(d, {n: S.PAPER_CAR[n] for n in ("m", "Ix", "Iy", "a1", "b1")})
