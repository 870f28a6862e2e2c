"""The compiled fixed-step kernel (RK4, Newmark) against the exact path and at its theoretical orders."""

from __future__ import annotations

import numba
import numpy as np
import pytest

from tests.conftest import PAPER_CAR, ROOT
from tests.reference import rel_rms
from tests.test_linear import smooth_road
from vehid_cli.config import load_config
from vehid_cli.identify.task import build_task
from vehid_cli.io.measurement import time_grid
from vehid_cli.models.effects import effect_rows
from vehid_cli.models.fullcar import assemble
from vehid_cli.sim.kernel import cubic_spring, integrate, integrate_blocks
from vehid_cli.sim.linear import simulate
from vehid_cli.sim.nonlinear import fullcar_struts, simulate_fullcar
from vehid_cli.sim.rk4 import _cache_key, _inlined

K3 = 5e7  # N/m³: at 3 cm of deflection the cubic force is ~ the linear spring's, so the car is clearly nonlinear
KNOT = 8e-3  # s: the test road is linear between knots every 8 ms, so every step size below samples it exactly


def knotted_road(t):
    """The smooth road, piecewise linear between knots every KNOT s: the same input at every dt dividing KNOT."""
    knots = np.arange(0.0, t[-1] + KNOT, KNOT)
    heights = smooth_road(knots)
    return np.stack([np.interp(t, knots, heights[:, c]) for c in range(4)], axis=-1)


def orders(errors):
    return np.log2(np.array(errors[:-1]) / np.array(errors[1:]))


@pytest.mark.parametrize(("method", "order", "tol_1ms"), [("rk4", 4, 1e-6), ("newmark", 2, 1e-3)])
def test_linear_car_agrees_with_exact_path_and_converges(method, order, tol_1ms):
    """Zero strut force: the kernel is the linear car, so its difference from the exact FOH path is the scheme error."""
    mats = assemble(PAPER_CAR)
    errors = []
    for dt in (4e-3, 2e-3, 1e-3):
        t = time_grid(1.5, dt)
        road = smooth_road(t)
        exact = simulate(mats, road, dt, "exact")
        r, res = simulate_fullcar(mats, road, dt, method)
        assert res.unconverged.sum() == 0
        errors.append(rel_rms(r.acc, exact.acc))
        assert rel_rms(r.disp, exact.disp) < errors[-1]  # displacements are smoother than accelerations
    assert errors[-1] < tol_1ms, errors
    p = orders(errors)
    assert np.all((p > order - 0.3) & (p < order + 0.4)), (errors, p)


@pytest.fixture(scope="module")
def cubic_reference():
    """RK4 at dt = 1/16 ms on the cubic-strut car: the fine-step reference (its own error ~ 1e-12 relative)."""
    mats = assemble(PAPER_CAR)
    dt = KNOT / 128
    t = time_grid(1.0, dt)
    r, _ = simulate_fullcar(mats, knotted_road(t), dt, "rk4", cubic_spring, [K3])
    return mats, t, r


@pytest.mark.parametrize(("method", "order", "strides"), [("rk4", 4, (32, 16, 8, 4)), ("newmark", 2, (16, 8, 4))])
def test_cubic_strut_converges_at_theoretical_order(cubic_reference, method, order, strides):
    """dt-halving on a strongly nonlinear car (k3 d³ in every strut): RK4 at order 4, Newmark at order 2."""
    mats, t_ref, ref = cubic_reference
    linear = simulate(mats, knotted_road(t_ref), t_ref[1], "exact")
    assert rel_rms(linear.acc, ref.acc) > 0.05  # the cubic spring matters
    errors = []
    for stride in strides:
        dt = stride * t_ref[1]
        t = t_ref[::stride]
        r, res = simulate_fullcar(mats, knotted_road(t), dt, method, cubic_spring, [K3])
        assert res.unconverged.sum() == 0
        errors.append(rel_rms(r.acc, ref.acc[::stride]))
    p = orders(errors)
    assert np.all((p > order - 0.3) & (p < order + 0.4)), (errors, p)


def test_batch_of_force_parameters_equals_one_at_a_time():
    t = time_grid(0.6, 1e-3)
    road = knotted_road(t)
    k3 = np.array([[0.0], [2e7], [5e7]])
    masses = np.array([1100.0, 1300.0, 1500.0])
    mats = assemble({**PAPER_CAR, "m": masses})
    for method in ("rk4", "newmark"):
        rb, _ = simulate_fullcar(mats, road, 1e-3, method, cubic_spring, k3)
        for i in range(3):
            r1, _ = simulate_fullcar(assemble(dict(PAPER_CAR, m=masses[i])), road, 1e-3, method, cubic_spring, k3[i])
            np.testing.assert_allclose(rb.acc[i], r1.acc, rtol=1e-12, atol=1e-12)


def test_strut_forces_and_generic_structure():
    """The kernel on a bare 1-DOF mass on a cubic spring driven through E: forces come back as k3 d³."""
    m, k, dt = 2.0, 800.0, 1e-3
    t = time_grid(0.5, dt)
    y = 0.01 * np.sin(2 * np.pi * 3 * t)[:, None]
    res = integrate("rk4", [[m]], [[0.0]], [[k]], [[0.0]], y, dt, cubic_spring, [1e6], D=[[1.0]], E=[[-1.0]])
    d = res.q[0, :, 0] - y[:, 0]
    np.testing.assert_allclose(res.force[0, :, 0], 1e6 * d**3, rtol=1e-12, atol=1e-18)
    np.testing.assert_allclose(m * res.qdd[0, :, 0], -k * res.q[0, :, 0] - res.force[0, :, 0], rtol=1e-9, atol=1e-12)
    with pytest.raises(ValueError, match="unknown method"):
        integrate("euler", [[m]], [[0.0]], [[k]], [[0.0]], y, dt)


def _hysteretic_cars():
    """Three cars with Bouc-Wen struts and damped tyres (the road drives the tyre struts: the slopes' right limits
    at the samples matter) on a random road, as the kernel's inputs, and a knotted road 0.6 s long."""
    masses = np.array([1100.0, 1300.0, 1500.0])
    mats = assemble({**PAPER_CAR, "m": masses})
    effects = {"hysteresis": {"alpha_f": 3e4, "alpha_r": 3e4, "beta": 2e4, "gamma": 2e4}, "tyre_damping": {}}
    es = effect_rows(effects, PAPER_CAR["cf"], PAPER_CAR["cr"], (3,))
    tyre = np.zeros((3, 4, 7))
    tyre[:, :, 3:] = np.eye(4)
    D = np.concatenate([fullcar_struts(mats), tyre], axis=1)
    E = np.concatenate([np.zeros((4, 4)), -np.eye(4)], axis=0)
    road = 5 * knotted_road(time_grid(0.6, 1e-3))
    return (mats.M, mats.C, mats.K, mats.B, road, 1e-3, es.law, es.rows, es.n_z), {"D": D, "E": E}


@pytest.mark.parametrize("block", [2, 7, 64, 599])
def test_blocks_equal_one_call(block):
    """A record integrated in time blocks, the state carried from each to the next (integrate_blocks), gives the
    numbers of one call bit for bit (a last block of one sample joins the one before); so does a call resumed by
    hand from a previous call's state (start, q0, v0, z0)."""
    args, struts = _hysteretic_cars()
    one = integrate("rk4", *args, **struts)
    assert np.ptp(one.z) > 0 and np.all(np.isfinite(one.q))  # the hysteresis is active
    parts = list(integrate_blocks(*args, **struts, block=block, forces=True))
    assert all(r.q.shape[1] >= 2 for _, r in parts) and parts[0][0] == 0
    for field in ("q", "qd", "qdd", "force", "z"):
        joined = np.concatenate([getattr(r, field) for _, r in parts], axis=1)
        np.testing.assert_array_equal(joined, getattr(one, field), err_msg=field)
    cut = min(block, 300)
    head = integrate("rk4", *args, **struts, stop=cut)
    rest = integrate("rk4", *args, **struts, start=cut, q0=head.q[:, -1], v0=head.qd[:, -1], z0=head.z[:, -1])
    np.testing.assert_array_equal(np.concatenate([head.qdd, rest.qdd], axis=1), one.qdd)
    np.testing.assert_array_equal(rest.state, one.state)


def test_resuming_is_rk4_only_and_needs_the_state():
    args, struts = _hysteretic_cars()
    with pytest.raises(ValueError, match="only the rk4 kernel"):
        integrate("newmark", *args, **struts, start=5, q0=np.zeros(7))
    with pytest.raises(ValueError, match="needs the state"):
        integrate("rk4", *args, **struts, start=5)
    skipped = integrate("rk4", *args, **struts, start=0, stop=10, forces=False)
    assert skipped.force.shape[1] == 0 and skipped.q.shape[1] == 10


def test_long_record_outputs_in_blocks_equal_one_simulation():
    """Experiment.outputs on a record longer than LONG_BLOCKS blocks runs the kernel in time blocks and keeps only
    the layout's channels: the same channels as reading one whole simulation, bit for bit."""
    config = load_config(
        ROOT / "configs" / "effects" / "hysteresis.yaml",
        ["road.bump=null", "road.random.iso_class=C", "simulation.duration=10", "simulation.substeps=2"],
    )
    exp = build_task(config).experiment
    values = {"m": np.array([1200.0, 1300.0, 1250.0]), "hysteresis.beta": np.array([1e4, 2e4, 3e4])}
    assert exp.blocked(values)
    blocked, whole = exp.outputs(values), exp.read(exp.simulate(values))
    assert set(blocked) == set(whole)
    for family in whole:
        np.testing.assert_array_equal(blocked[family], whole[family])


def test_the_composed_laws_and_the_librarys_are_inlined_into_the_rk4_loop():
    """rk4._inlined recompiles a law with inline="always" unless its options would be lost (fastmath, ...): every
    law the package composes or ships must qualify (a law left as a call costs ~25 ns four times per step: the car's
    kernel ran 1.7 x slower when the compiled functions' default nogil made them fail the check); and the loop's cache
    key follows the law's options, so that a loop compiled before such a change is not loaded after it."""
    law = effect_rows({"hysteresis": {}}, 1000.0, 1000.0, ()).law
    for force in (law, cubic_spring):
        inlined, _ = _inlined(force)
        assert inlined is not force and inlined.targetoptions.get("inline") == "always", force.targetoptions
    fastmath = numba.njit(fastmath=True)(cubic_spring.py_func)
    assert _inlined(fastmath)[0] is fastmath  # (the check can fail: such a law stays a call)
    assert _cache_key(fastmath, "python", 1) != _cache_key(cubic_spring, "python", 1)
