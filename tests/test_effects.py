"""The effect library on the full car: limits (zero strength = the linear car), orders, physics, visibility."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import BASE_CONFIG, PAPER_CAR, ROOT, vehid
from tests.reference import rel_rms
from tests.test_kernel import knotted_road, orders
from vehid_cli.config import load_config
from vehid_cli.identify.experiment import build_experiment
from vehid_cli.io.measurement import read_measurement, time_grid
from vehid_cli.models.effects import LIBRARY, CarScale, effect_rows, strut_effects
from vehid_cli.models.effects.backlash import STABLE, car, stiffest_contact
from vehid_cli.models.fullcar import assemble
from vehid_cli.sim.kernel import integrate
from vehid_cli.sim.nonlinear import fullcar_struts, simulate_effects

EFFECTS_DIR = ROOT / "configs" / "effects"
NOISE = 0.05  # the level each truth config's effect must stand out of (RMS, relative to each channel's std)


def truth(name: str):
    """The shipped truth config of an effect: the paper's car plus that effect."""
    return load_config(EFFECTS_DIR / f"{name}.yaml")


@pytest.fixture(scope="module")
def linear_bump():
    """The paper's car on the paper's bump by the exact (first-order-hold) path."""
    return build_experiment(load_config(BASE_CONFIG)).simulate()


def test_every_effect_has_a_truth_config_that_declares_it():
    assert sorted(p.stem for p in EFFECTS_DIR.glob("*.yaml")) == sorted(LIBRARY)
    for name in LIBRARY:
        cfg = truth(name)
        assert list(cfg.vehicle.effects) == [name] and cfg.simulation.integrator == "rk4"


@pytest.mark.parametrize("name", sorted(LIBRARY))
def test_zero_strength_is_the_linear_car(name, linear_bump):
    """Strength 0 (shape parameters at their truth values): RK4 at 1 ms differs from the exact path by its
    scheme error only, and substeps shrink it by the fourth power of the step."""
    e = LIBRARY[name]
    zero = {f"{name}.{n}": 0.0 for n in e.names() if e.param(n).name == e.strength}
    exp = build_experiment(truth(name))
    err1 = rel_rms(exp.simulate(zero).acc, linear_bump.acc)
    assert err1 < 1e-6, err1
    fine = build_experiment(load_config(EFFECTS_DIR / f"{name}.yaml", ["simulation.substeps=2"]))
    err2 = rel_rms(fine.simulate(zero).acc, linear_bump.acc)
    assert 8 < err1 / err2 < 24, (err1, err2)  # 2^4 = 16


def test_all_effects_at_zero_strength_together_are_the_linear_car(linear_bump):
    cfg = load_config(BASE_CONFIG, ["simulation.integrator=rk4"])
    exp = build_experiment(cfg)
    zero = {f"{name}.{n}": 0.0 for name, e in LIBRARY.items() for n in e.names() if e.param(n).name == e.strength}
    r = exp.simulate(zero)
    assert rel_rms(r.acc, linear_bump.acc) < 1e-6
    assert rel_rms(r.disp, linear_bump.disp) < 1e-7


SMOOTH_EFFECTS = {  # every force smooth in (d, dd): RK4 keeps its order
    "asymmetric_damping": {"dc_f": 2800.0, "dc_r": 3500.0, "v_eps": 0.2},
    "gas_spring": {"F0_f": 2500.0, "F0_r": 2500.0, "L": 0.08},
    "tyre_damping": {"ct_f": 500.0, "ct_r": 500.0},
    "damper_lag": {"T_f": 0.01, "T_r": 0.01},
}


@pytest.mark.parametrize("effects", [{}, SMOOTH_EFFECTS], ids=["linear", "smooth-effects"])
def test_kernel_path_converges_at_order_four(effects):
    """dt-halving by substeps on a road linear between 8 ms knots (the same input at every step), against
    the same path at 1/16 of the coarsest step."""
    mats = assemble(PAPER_CAR)
    dt = 4e-3
    t = time_grid(1.0, dt)
    road = knotted_road(t)

    def run(substeps):
        return simulate_effects(mats, PAPER_CAR["cf"], PAPER_CAR["cr"], effects, road, dt, "rk4", substeps).acc

    ref = run(64)
    if effects:
        linear = simulate_effects(mats, PAPER_CAR["cf"], PAPER_CAR["cr"], {}, road, dt, "rk4", 64).acc
        assert rel_rms(linear, ref) > 0.1  # the effects matter
    errors = [rel_rms(run(s), ref) for s in (1, 2, 4)]
    p = orders(errors)
    assert np.all((p > 3.7) & (p < 4.4)), (errors, p)


def free_decay(effects, lift=0.02, duration=2.0, dt=5e-4, car=PAPER_CAR):
    """The car released from rest with its body lifted by `lift` [m] on a level road: the kernel result
    and the matrices (strut forces of the effects in res.force)."""
    mats = assemble(car)
    es = effect_rows(effects, car["cf"], car["cr"], ())
    q0 = np.zeros(7)
    q0[0] = lift
    t = time_grid(duration, dt)
    res = integrate(
        "rk4",
        mats.M,
        mats.C,
        mats.K,
        mats.B,
        np.zeros((t.size, 4)),
        dt,
        strut_effects,
        es.rows,
        es.n_z,
        D=fullcar_struts(mats),
        q0=q0,
    )
    return t, res, mats


def test_coulomb_friction_dissipates_and_the_energy_balance_closes():
    """Free decay: E(0) - E(t) = the work of the linear dampers plus that of the friction forces; the friction
    work is positive (a dissipative force), the energy never grows, and ends far below the linear car's."""
    t, res, mats = free_decay({"coulomb_friction": {"Fc_f": 150.0, "Fc_r": 150.0}})
    _, lin, _ = free_decay({})
    q, v = res.q[0], res.qd[0]

    def energy(q, v):
        return 0.5 * np.einsum("ni,ij,nj->n", v, mats.M, v) + 0.5 * np.einsum("ni,ij,nj->n", q, mats.K, q)

    E = energy(q, v)
    dd = v @ fullcar_struts(mats).T
    friction_power = np.sum(res.force[0] * dd, axis=1)
    damper_power = np.einsum("ni,ij,nj->n", v, mats.C, v)
    dt = t[1] - t[0]

    def work(power):
        return np.concatenate([[0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) * dt)])

    assert np.all(friction_power >= 0.0)
    # trapezoidal quadrature of the power: its error (friction switches on within v_eps) sets the tolerance
    np.testing.assert_allclose(E[0] - E, work(damper_power) + work(friction_power), atol=1e-4 * E[0])
    assert work(friction_power)[-1] > 0.05 * E[0]
    E_lin = energy(lin.q[0], lin.qd[0])
    assert np.all(np.diff(E) <= 1e-9 * E[0]) and E[-1] < 0.1 * E_lin[-1]  # never gains, ends far lower


@pytest.mark.parametrize(
    "effects",
    [
        {"progressive_spring": {"k3_f": 2e7, "k3_r": 3e7}},
        {"gas_spring": {"F0_f": 2500.0, "F0_r": 2500.0, "L": 0.08}},
        {"hysteresis": {"alpha_f": 3e4, "alpha_r": 3e4}},
    ],
    ids=["progressive", "gas", "hysteresis"],
)
def test_level_road_lift_is_a_rigid_lift(effects):
    """Road raised by h under all four tyres: the car ends lifted rigidly by h (x = x_i = h, no roll or pitch),
    since the linear and nonlinear springs see no deflection there (the linear static solution K q = B y)."""
    h, dt = 0.03, 1e-3
    t = time_grid(6.0, dt)
    ramp = np.clip((t - 0.1) / 0.5, 0.0, 1.0)
    road = h * (0.5 - 0.5 * np.cos(np.pi * ramp))[:, None] * np.ones(4)
    mats = assemble(PAPER_CAR)
    r = simulate_effects(mats, PAPER_CAR["cf"], PAPER_CAR["cr"], effects, road, dt, "rk4")
    expected = np.linalg.solve(mats.K, mats.B @ road[-1])
    np.testing.assert_allclose(expected, [h, 0, 0, h, h, h, h], atol=1e-15)
    tol = 0.03 if "hysteresis" in effects else 1e-4  # Bouc-Wen keeps a residual force: it settles near, not at
    np.testing.assert_allclose(r.q[-1], expected, atol=tol * h)
    assert np.abs(r.acc[-1]).max() < 1e-3


def bounce_frequency(effects, lift):
    """Body bounce frequency [Hz] of the undamped car in free vibration from a body lift [m] (zero crossings)."""
    car = dict(PAPER_CAR, cf=0.0, cr=0.0)
    t, res, _ = free_decay(effects, lift=lift, duration=3.0, dt=1e-3, car=car)
    x = res.q[0, :, 0]
    up = np.flatnonzero((x[:-1] < 0) & (x[1:] >= 0))
    tc = t[up] - x[up] / (x[up + 1] - x[up]) * (t[1] - t[0])  # linear interpolation of the crossings
    return (len(tc) - 1) / (tc[-1] - tc[0])


def test_progressive_spring_raises_the_bounce_frequency_with_amplitude():
    """A hardening spring: the bounce frequency rises with amplitude, and small amplitudes give the linear one."""
    effects = {"progressive_spring": {"k3_f": 2e7, "k3_r": 3e7}}
    f_lin = bounce_frequency({}, 0.03)
    w = assemble(dict(PAPER_CAR, cf=0.0, cr=0.0)).natural_frequencies() / (2 * np.pi)
    assert np.min(np.abs(w - f_lin)) < 0.02 * f_lin  # zero crossings see the bounce mode of the linear car
    f_small, f_large = bounce_frequency(effects, 0.002), bounce_frequency(effects, 0.04)
    assert abs(f_small - f_lin) < 0.01 * f_lin
    assert f_large > 1.05 * f_lin, (f_lin, f_small, f_large)


def test_gas_spring_force_is_the_polytropic_law():
    """The law's suspension force against the polytropic charge written the other way round: compression
    s = -d squeezes the gas column L to L - s, F_out = F0 (L / (L - s))^kappa, minus preload and linear part."""
    F0, L, kap = 2500.0, 0.08, 1.4
    es = effect_rows({"gas_spring": {"F0_f": F0, "F0_r": F0, "L": L, "kappa": kap}}, 2800.0, 3500.0, ())
    for s in (-0.03, -0.01, 0.0, 0.01, 0.03, 0.05):  # compression [m]
        f = np.empty(4)
        strut_effects(np.full(4, -s), np.zeros(4), np.zeros(0), es.rows[0], f, np.zeros(0))
        push_out = F0 * (L / (L - s)) ** kap - F0 - F0 * kap * s / L  # nonlinear part, pushing the strut out
        np.testing.assert_allclose(f, -push_out, rtol=1e-12, atol=1e-9)
    # beyond the linear part the charge pushes out at either stroke, harder in compression: it stiffens there
    f_c, f_e = np.empty(4), np.empty(4)
    strut_effects(np.full(4, -0.03), np.zeros(4), np.zeros(0), es.rows[0], f_c, np.zeros(0))
    strut_effects(np.full(4, 0.03), np.zeros(4), np.zeros(0), es.rows[0], f_e, np.zeros(0))
    assert np.all(f_c < f_e) and np.all(f_e < 0)


@pytest.mark.parametrize("name", sorted(LIBRARY))
def test_each_truth_effect_stands_out_of_five_percent_noise(name, linear_bump):
    """The shipped truth configs: the effect changes every body-point acceleration on the paper's bump by
    more than 5 % noise would (RMS of the change over each channel's standard deviation)."""
    r = build_experiment(truth(name)).simulate()
    assert np.all(np.isfinite(r.acc))
    change = np.sqrt(np.mean((r.acc - linear_bump.acc) ** 2, axis=0)) / linear_bump.acc.std(axis=0)
    assert np.all(change > 1.5 * NOISE), change


def test_batched_effect_parameters_equal_one_at_a_time():
    """Experiment.simulate over a batch of effect and car parameters is the same as one car at a time."""
    exp = build_experiment(load_config(EFFECTS_DIR / "hysteresis.yaml", ["simulation.duration=0.8"]))
    values = {
        "m": np.array([1200.0, 1300.0, 1400.0]),
        "hysteresis.alpha_f": np.array([0.0, 3e4, 6e4]),
        "backlash.gap_r": np.array([0.0, 0.002, 0.004]),
    }
    batch = exp.simulate(values)
    assert batch.acc.shape == (3, 800, 4)
    for i in range(3):
        one = exp.simulate({k: v[i] for k, v in values.items()})
        np.testing.assert_allclose(batch.acc[i], one.acc, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(batch.q[i], one.q, rtol=1e-12, atol=1e-15)
    assert rel_rms(batch.acc[2], batch.acc[0]) > 0.05


def test_newmark_with_effects_agrees_with_rk4():
    """The second kernel scheme on the same nonlinear car: close to RK4 at 1 ms (second-order error)."""
    rk4 = build_experiment(truth("hysteresis")).simulate()
    nm = build_experiment(load_config(EFFECTS_DIR / "hysteresis.yaml", ["simulation.integrator=newmark"])).simulate()
    assert rel_rms(nm.acc, rk4.acc) < 0.02


def test_simulate_writes_data_with_the_effect(tmp_path, linear_bump):
    out = tmp_path / "run.csv"
    res = vehid("simulate", EFFECTS_DIR / "backlash.yaml", "-o", out, "--set", "noise.level=0")
    assert res.returncode == 0, res.stderr
    m = read_measurement(out)
    clean = build_experiment(truth("backlash")).simulate()
    np.testing.assert_allclose(m.acc, clean.acc, rtol=1e-6, atol=1e-6 * np.abs(clean.acc).max())
    assert rel_rms(m.acc, linear_bump.acc) > NOISE


@pytest.mark.parametrize(
    ("overrides", "key", "words"),
    [
        (["vehicle.effects.hysterisis.alpha_f=1"], "vehicle.effects.hysterisis", "did you mean 'hysteresis'"),
        (["vehicle.effects.hysteresis.alpah_f=1"], "vehicle.effects.hysteresis.alpah_f", "did you mean 'alpha_f'"),
        (["vehicle.effects.hysteresis.alpha_f=-5"], "vehicle.effects.hysteresis.alpha_f", "physical range"),
        (["vehicle.effects.asymmetric_damping.dc_f=6000"], "vehicle.effects.asymmetric_damping.dc_f", "2 cf"),
        (["simulation.integrator=exact"], "simulation.integrator", "rk4"),
    ],
)
def test_bad_effects_input_exits_2_naming_the_key(overrides, key, words, tmp_path):
    args = [a for o in overrides for a in ("--set", o)]
    res = vehid("simulate", EFFECTS_DIR / "hysteresis.yaml", "-o", tmp_path / "x.csv", *args)
    assert res.returncode == 2, res.stderr
    assert f"'{key}'" in res.stderr and words in res.stderr and "Traceback" not in res.stderr
    assert not (tmp_path / "x.csv").exists()


def test_effect_parameters_can_be_unknowns():
    """identify.unknowns may name a declared effect's parameters: the task simulates them, the truth is zero-cost."""
    from vehid_cli.identify.task import build_task

    hyst = ROOT / "configs" / "effects" / "hysteresis.yaml"
    cfg = load_config(hyst, ["identify.unknowns=[m,hysteresis.alpha_f]", "noise.level=0", "identify.objective=wls"])
    task = build_task(cfg)
    assert task.names == ("m", "hysteresis.alpha_f")
    assert task.nominal[1] == 30000.0 and task.lower[1] == 0.7 * 30000.0
    costs = task.problem(task.reference(0)).cost(np.array([task.nominal, [1300.0, 0.8 * 30000.0]]))
    assert costs[0] == pytest.approx(0.0, abs=1e-12) and costs[1] > 1e-6


@pytest.mark.parametrize(
    ("unknowns", "message"),
    [("[m,hysteresis.alfa_f]", "did you mean 'hysteresis.alpha_f'"), ("[m,hysteresis.alpha_f]", "identify.limits")],
)
def test_bad_effect_unknowns_are_named(unknowns, message):
    from vehid_cli.core.errors import InputError

    base = ROOT / "configs" / "effects" / "hysteresis.yaml"
    sets = [f"identify.unknowns={unknowns}"]
    if message == "identify.limits":
        sets.append("vehicle.effects.hysteresis.alpha_f=0")
    with pytest.raises(InputError, match=message.replace("(", r"\(")):
        load_config(base, sets)


def test_backlash_contact_bound_is_the_rk4_stability_edge():
    """The car candidate's contact stiffness stops below the stiffness at which one RK4 step of the piston's state
    (eigenvalue -k / c) stops damping it: the growth factor of RK4's polynomial crosses 1 there; a finer step moves
    the edge out until the fixed 1e8 N/m bound applies."""

    def growth(z: float) -> float:
        return abs(1 + z + z**2 / 2 + z**3 / 6 + z**4 / 24)

    c, h = 2800.0, 1e-3
    k = stiffest_contact(c, h)
    assert growth(-0.999 * k * h / c) < 1.0 < growth(-1.001 * k * h / c)
    upper = car(CarScale(c, 3500.0, h)).shape_limits["backlash.k_contact"][1]
    assert upper == pytest.approx(STABLE * k, rel=1e-12)  # the softer axle's damping sets it
    assert car(CarScale(c, 3500.0, h / 4)).shape_limits["backlash.k_contact"][1] == pytest.approx(4 * upper)
    assert car(CarScale(c, 3500.0, 1e-5)).shape_limits["backlash.k_contact"][1] == 1e8
    assert car(CarScale(c, 3500.0, None)).shape_limits["backlash.k_contact"][1] == 1e8  # Newmark: not RK4's edge
