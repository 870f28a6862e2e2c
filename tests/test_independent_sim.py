"""Checks of the independent full-car simulator (tests/independent_sim.py) against closed forms and vehid_cli."""

from __future__ import annotations

import ast

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from tests import independent_sim as S
from tests.conftest import BASE_CONFIG

SPEED = 20.0 / 3.6  # m/s
LAST_KINK = 0.1 + 2.6 / SPEED + 0.1 / SPEED  # s: the rear tyres leave the ramp


def rel_max(x: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Max abs error per channel over the channel's range."""
    return np.abs(x - ref).max(axis=0) / (ref.max(axis=0) - ref.min(axis=0))


@pytest.fixture(scope="module")
def linear():
    return S.simulate(S.PAPER_CAR)


@pytest.fixture(scope="module")
def vehid_run():
    from vehid_cli.config import load_config
    from vehid_cli.identify.experiment import build_experiment

    ex = build_experiment(load_config(BASE_CONFIG))
    return ex, ex.simulate()


# 1. physics against closed forms


def test_module_is_independent_of_vehid_cli():
    tree = ast.parse(open(S.__file__, encoding="utf-8").read())
    modules = {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    modules |= {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    assert not any(m.startswith(("vehid", "tests")) for m in modules), modules


def test_zero_road_stays_at_rest_with_every_effect():
    sim = S.simulate({}, {name: None for name in S.EFFECTS}, heights=(0, 0, 0, 0), duration=0.5)
    for key in ("acc", "disp", "d", "v", "extra", "tyre", "state"):
        assert np.all(sim[key] == 0.0), key


def test_sign_conventions():
    car = S.FullCar(S.PAPER_CAR)
    q = np.zeros((7, 1))
    q[2] = 0.01  # positive pitch raises the rear
    assert np.allclose(car.body_points(q)[:, 0], [-0.013, -0.013, 0.013, 0.013])
    q[:] = 0.0
    q[1] = 0.01  # positive roll raises side b1 (corners 1, 4)
    assert np.allclose(car.body_points(q)[:, 0], [0.0075, -0.0075, -0.0075, 0.0075])
    sim = S.simulate({}, heights=(0.05, 0.05, 0.05, 0.05), duration=1.0)
    assert np.abs(sim["q"][:, 1]).max() < 1e-12 * np.abs(sim["q"][:, 0]).max()  # symmetric car and road: no roll
    early = sim["t"] < 0.1 + 2.6 / SPEED  # only the front tyres have met the bump: nose up, theta < 0
    assert sim["q"][early, 2].min() < -1e-3 and sim["q"][early, 2].max() < 1e-6


def test_energy_conserved_without_damping():
    sim = S.simulate({"cf": 0.0, "cr": 0.0}, duration=2.0, rtol=1e-10, atol=1e-13)
    e = sim["energy"][sim["t"] > LAST_KINK]
    assert e.mean() > 100.0  # J: the bump left real energy in the car
    assert (e.max() - e.min()) / e.mean() < 1e-6


def test_static_deflection_under_a_level_road():
    """A long run with damping on a step of height h: every body point and wheel ends at h (no preload)."""
    sim = S.simulate({}, heights=(0.03, 0.03, 0.03, 0.03), duration=3.0)
    assert np.allclose(sim["q"][-1, [0, 3, 4, 5, 6]], 0.03, atol=1e-4)


# 2. agreement with the project's linear model


def test_agrees_with_vehid_cli_on_the_continuous_road(linear, vehid_run):
    ex, r = vehid_run
    assert np.array_equal(ex.t, linear["t"])
    assert np.abs(ex.road - linear["road"]).max() < 1e-15
    # vehid's exact integrator holds the road linear between the 1 ms samples (18 per 18 ms ramp): ~5e-4 of range
    assert rel_max(r.acc, linear["acc"]).max() < 1e-3
    assert rel_max(r.disp, linear["disp"]).max() < 1e-4


def test_agrees_with_vehid_cli_to_round_off_on_its_sampled_road(vehid_run):
    """The same road as vehid integrates (linear between samples): the two models are the same to ~1e-11."""
    ex, r = vehid_run
    t, road = ex.t, ex.road
    slope = np.diff(road, axis=0) / np.diff(t)[:, None]

    def road_fn(tt):
        tt = np.atleast_1d(tt)
        k = np.clip(np.searchsorted(t, tt, side="right") - 1, 0, t.size - 2)
        return (road[k] + slope[k] * (tt - t[k])[:, None]).T, slope[k].T

    kinks = t[1:-1][np.any(np.diff(slope, axis=0) != 0.0, axis=1)]
    sim = S.run(S.FullCar(S.PAPER_CAR, None, road_fn), t, kinks, rtol=1e-11, atol=1e-14)
    assert rel_max(r.acc, sim["acc"]).max() < 1e-9
    assert rel_max(r.disp, sim["disp"]).max() < 1e-9


# 3. Bouc-Wen saturation


def integrate_bouc_wen(v, A, beta, gamma, duration):
    """zeta(t) [m] of the Bouc-Wen law alone under a constant strut velocity v [m/s], from zeta = 0."""
    sol = solve_ivp(
        lambda t, z: S.bouc_wen_rate(z, v, A, beta, gamma), (0.0, duration), [0.0], rtol=1e-10, atol=1e-14,
        dense_output=True,
    )  # fmt: skip
    return sol


@pytest.mark.parametrize("A, beta, gamma", [(1.0, 1e4, 1e4), (1.5, 2e4, 1e4), (0.5, 3e4, -1e4)])
@pytest.mark.parametrize("v", [0.2, -0.3])
def test_bouc_wen_saturates(A, beta, gamma, v):
    z_sat = np.sqrt(A / (beta + gamma))
    sol = integrate_bouc_wen(v, A, beta, gamma, duration=1.0)  # a stroke of 0.2-0.3 m, >> z_sat
    assert sol.y[0, -1] == pytest.approx(np.sign(v) * z_sat, rel=1e-8)
    # the closed form on the way there: dzeta/dx = A - (beta + gamma) zeta^2 (monotone stroke x = |v| t)
    tt = np.linspace(0.0, 0.05, 11)
    closed = np.sign(v) * z_sat * np.tanh(np.sqrt(A * (beta + gamma)) * abs(v) * tt)
    assert np.allclose(sol.sol(tt)[0], closed, rtol=1e-6, atol=1e-12)


# 4. every effect: zero force at rest, a visible change when present


@pytest.mark.parametrize("name", S.EFFECTS)
def test_effect_force_zero_at_rest(name):
    eff = S.effect_params({name: None})
    zero = np.zeros((4, 1))
    assert np.all(S.extra_strut_force(zero, zero, eff, zeta=zero) == 0.0)


@pytest.fixture(scope="module")
def short_linear():
    return S.simulate({}, duration=1.0)


@pytest.mark.parametrize("name", S.EFFECTS)
def test_effect_changes_response(name, short_linear):
    sim = S.simulate({}, {name: None}, duration=1.0)
    change = rel_max(sim["acc"], short_linear["acc"]).max()
    assert change > 0.02, f"{name} changed acc by only {change:.2%} of range"
    assert np.isfinite(sim["acc"]).all()


@pytest.mark.parametrize("name", S.OUTSIDE_LIBRARY)
def test_laws_outside_the_library_are_zero_at_rest_and_change_the_response(name, short_linear):
    """Issue 25's held-back kinds (a quadratic and a digressive damper, Stribeck friction, a progressive tyre)."""
    eff = S.effect_params({name: None})
    zero = np.zeros((4, 1))
    assert np.all(S.outside_strut_force(zero, zero, eff) == 0.0) and np.all(S.outside_tyre_force(zero, eff) == 0.0)
    sim = S.simulate({}, {name: None}, duration=1.0)
    change = rel_max(sim["acc"], short_linear["acc"]).max()
    assert change > 0.02, f"{name} changed acc by only {change:.2%} of range"


def test_the_digressive_damper_keeps_c_below_its_knee_and_share_c_above():
    """The blow-off law's slope from central differences: the linear damper's c below the knee, share * c above."""
    eff = S.effect_params({"digressive_damper": None})
    c = S.per_corner(S.PAPER_CAR["cf"], S.PAPER_CAR["cr"])
    knee, share = eff["digressive_damper"]["v_knee"], eff["digressive_damper"]["share"]
    h = 1e-6
    for v, slope in ((0.5 * knee, c), (3.0 * knee, share * c), (-3.0 * knee, share * c)):
        vv = np.full((4, 1), v)
        total = (c * (vv + h) + S.outside_strut_force(0.0, vv + h, eff)) - (
            c * (vv - h) + S.outside_strut_force(0.0, vv - h, eff)
        )
        np.testing.assert_allclose(total / (2 * h), slope, rtol=1e-6)


def test_effects_combine_and_laws_match_their_definitions():
    effects = {
        "hysteresis": dict(alpha_f=2e4, alpha_r=4e4, beta=5e3, gamma=1.5e4, A=0.8),
        "coulomb_friction": dict(Fc_f=100.0, Fc_r=200.0, v_eps=0.02),
        "bump_stop": dict(k_stop_f=1e5, k_stop_r=3e5, gap_f=0.015, gap_r=0.025, compression_only=1.0),
        "damper_lag": dict(T_f=0.005, T_r=0.02),
    }
    sim = S.simulate({}, effects, duration=1.0)
    d, v = sim["d"], sim["v"]
    zeta = sim["state"][:, 14:18]
    fd = sim["state"][:, 18:22]
    ks, cs = np.array([45e3, 45e3, 80e3, 80e3]), np.array([2800.0, 2800.0, 3500.0, 3500.0])
    gap, k = np.array([0.015, 0.015, 0.025, 0.025]), np.array([1e5, 1e5, 3e5, 3e5])
    expected = (
        np.array([2e4, 2e4, 4e4, 4e4]) * zeta
        + np.array([100.0, 100.0, 200.0, 200.0]) * np.tanh(v / 0.02)
        + np.where(d < -gap, k * (d + gap), 0.0)
        + fd - cs * v
    )  # fmt: skip
    assert np.allclose(sim["extra"], expected, rtol=1e-12, atol=1e-9)
    assert (d < -gap).any()  # the stop engaged
    # body Newton check: m * bounce acc = -sum of strut forces
    F = ks * d + cs * v + sim["extra"]
    bounce_acc = np.gradient(sim["qd"][:, 0], sim["t"])
    assert np.allclose(1300.0 * bounce_acc[5:-5], -F.sum(axis=1)[5:-5], atol=0.02 * np.abs(F.sum(axis=1)).max())


def test_gas_spring_and_asymmetric_laws():
    eff = S.effect_params({"gas_spring": dict(F0_f=1000.0, F0_r=3000.0, L=0.2, kappa=1.3)})
    d = np.array([[-0.05], [0.05], [-0.05], [0.05]])
    F0 = np.array([[1000.0], [1000.0], [3000.0], [3000.0]])
    expected = F0 * (1 - (1 + d / 0.2) ** -1.3) - F0 * 1.3 * d / 0.2
    assert np.allclose(S.extra_strut_force(d, 0 * d, eff), expected)
    assert expected[0, 0] < 0 and expected[1, 0] < 0  # stiffer in compression, softer in rebound
    eff = S.effect_params({"asymmetric_damping": dict(dc_f=1000.0, dc_r=1000.0, v_eps=1e-4)})
    v = np.array([[1.0], [-1.0], [0.5], [-0.5]])
    f = 2800.0 * v[:, 0] + S.extra_strut_force(0 * v, v, eff)[:, 0]
    assert np.allclose(f, [3300.0 * 1.0, 2300.0 * -1.0, 3300.0 * 0.5, 2300.0 * -0.5])  # rebound c + dc/2


# output file


def test_write_run_noise_and_format(tmp_path, linear):
    from vehid_cli.io.measurement import read_measurement

    path = tmp_path / "run.csv"
    S.write_run(path, linear, noise_level=0.05, seed=7, comments=["independent simulator"])
    m = read_measurement(path)
    assert np.allclose(m.road, linear["road"], rtol=1e-11, atol=1e-15)
    clean = np.hstack([linear["acc"], linear["disp"]])
    noisy = np.hstack([m.acc, m.disp])
    ratio = (noisy - clean).std(axis=0) / (0.05 * clean.std(axis=0))
    assert np.all(np.abs(ratio - 1.0) < 0.1)  # 3000 samples: the sample sd within ~4 % of sigma
    S.write_run(tmp_path / "again.csv", linear, noise_level=0.05, seed=7)
    assert (tmp_path / "again.csv").read_text() == path.read_text().split("\n", 1)[1]


def test_command_line(tmp_path):
    out = tmp_path / "cli.csv"
    hysteresis = "hysteresis:alpha_f=3e4,alpha_r=3e4,beta=1e4,gamma=1e4,A=1"
    argv = ["-o", str(out), "--set", "kf=54000", "--effect", hysteresis, "--noise", "0.05", "--seed", "1",
            "--duration", "0.5"]  # fmt: skip
    assert S.main(argv) == 0
    table = np.genfromtxt(out, delimiter=",", names=True)
    assert table.shape == (500,) and "disp4" in table.dtype.names
