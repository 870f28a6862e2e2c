"""Exact sensitivities (sim/sensitivity.py) against central differences of the simulator itself, and what uses them:
lsq's Levenberg–Marquardt on the exact linearisation reaches the same minimum as scipy's trust region on differences,
and the bound from exact sensitivities is the bound from central differences."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import yaml

from tests.conftest import BASE_CONFIG, ROOT
from vehid_cli.config import load_config
from vehid_cli.core.streams import run_streams
from vehid_cli.identify.crlb import cramer_rao
from vehid_cli.identify.experiment import build_experiment
from vehid_cli.identify.task import build_task
from vehid_cli.optimizers import get_optimizer
from vehid_cli.optimizers.base import Search
from vehid_cli.optimizers.lsq import STEP_SD, gauss_newton, polish
from vehid_cli.sim.modal import linear_foh
from vehid_cli.sim.sensitivity import central_points, linear_sensitivities

TOL = 1e-6  # relative to the largest derivative of each parameter and channel family


def _generic(theta: np.ndarray, parts: dict) -> tuple:
    """A 6-state, 3-input, 4-output system whose A, Bs, s0, Cy, Dy all depend on theta (2,), with its derivatives."""
    a, b = theta
    A = parts["A0"] + a * parts["A1"] + b**2 * parts["A2"]
    Bs = parts["B0"] + a * b * parts["B1"]
    s0 = parts["s0"] + np.sin(a) * parts["s1"]
    Cy = parts["C0"] + b * parts["C1"]
    Dy = parts["D0"] + a * parts["D1"]
    dA = np.stack([parts["A1"], 2 * b * parts["A2"]])
    dBs = np.stack([b * parts["B1"], a * parts["B1"]])
    ds0 = np.stack([np.cos(a) * parts["s1"], 0 * parts["s1"]])
    dCy = np.stack([0 * parts["C1"], parts["C1"]])
    dDy = np.stack([parts["D1"], 0 * parts["D1"]])
    return (A, Bs, s0, Cy, Dy), (dA, dBs, ds0, dCy, dDy)


def _random_parts(rng: np.random.Generator, ns: int, nu: int, ny: int) -> dict[str, np.ndarray]:
    """Random matrices of `_generic`'s system: a stable A0 (complex and real modes), the terms moving with theta."""
    return {
        "A0": rng.normal(size=(ns, ns)) * 20 - 30 * np.eye(ns), "A1": rng.normal(size=(ns, ns)) * 5,
        "A2": rng.normal(size=(ns, ns)) * 5, "B0": rng.normal(size=(ns, nu)), "B1": rng.normal(size=(ns, nu)),
        "C0": rng.normal(size=(ny, ns)), "C1": rng.normal(size=(ny, ns)), "D0": rng.normal(size=(ny, nu)),
        "D1": rng.normal(size=(ny, nu)), "s0": rng.normal(size=ns), "s1": rng.normal(size=ns),
    }  # fmt: skip


def test_generic_system_matches_central_differences_and_the_simulator():
    """Complex and real modes, an output matrix, feedthrough and start that move with the parameters: the outputs are
    linear_foh's to round-off, the derivatives its central differences to TOL (their own truncation is ~1e-10)."""
    rng = np.random.default_rng(1)
    ns, nu, ny, n, dt = 6, 3, 4, 2000, 1e-3
    parts = _random_parts(rng, ns, nu, ny)
    t = np.arange(n) * dt
    u = np.stack([np.sin(2 * np.pi * (3 + i) * t) + 0.3 * (t > 0.5 + 0.2 * i) for i in range(nu)], axis=-1)
    theta = np.array([0.3, 0.7])
    mats, derivs = _generic(theta, parts)
    assert np.any(np.abs(np.linalg.eigvals(mats[0]).imag) == 0) and np.any(np.linalg.eigvals(mats[0]).imag != 0)
    Y, dY, ok = linear_sensitivities(*(M[None] for M in mats[:2]), mats[2][None], u, dt, mats[3][None],
                                     mats[4][None], *(d[None] for d in derivs))  # fmt: skip
    assert ok.all()

    def simulate(th: np.ndarray) -> np.ndarray:
        (A, Bs, s0, Cy, Dy), _ = _generic(th, parts)
        return linear_foh(A[None], Bs[None], s0[None], u, dt, Cy[None], Dy[None])[0]

    assert np.max(np.abs(Y[0] - simulate(theta))) <= 1e-12 * np.max(np.abs(Y))
    h = 1e-5
    for j in range(2):
        e = h * np.eye(2)[j]
        fd = (simulate(theta + e) - simulate(theta - e)) / (2 * h)
        assert np.max(np.abs(dY[0, ..., j] - fd)) <= TOL * np.max(np.abs(fd))


def test_repeated_eigenvalues_are_refused():
    """Two equal eigenvalues: the perturbation formulas divide by their gap, so the candidate is flagged."""
    A = np.diag([-3.0, -3.0, -5.0])[None]
    Bs, s0, Cy, Dy = np.ones((1, 3, 1)), np.zeros((1, 3)), np.ones((1, 1, 3)), np.zeros((1, 1, 1))
    u = np.ones((10, 1))
    *_, ok = linear_sensitivities(A, Bs, s0, u, 0.01, Cy, Dy, np.ones((1, 1, 3, 3)), np.zeros((1, 1, 3, 1)),
                                  np.zeros((1, 1, 3)), np.zeros((1, 1, 1, 3)), np.zeros((1, 1, 1, 1)))  # fmt: skip
    assert not ok[0]


OFF_CORNER = [
    {"name": "acc_tower", "kind": "body_acc", "origin": "corner1", "x": -0.15, "y": -0.1},
    {"name": "acc_floor", "kind": "body_acc", "origin": "front_axle", "x": -0.9, "y": 0.4},
    {"name": "acc_cg", "kind": "body_acc", "x": 0.3, "y": -0.2},
    {"name": "disp_boot", "kind": "body_disp", "origin": "rear_axle", "x": -0.5, "y": 0.1},
    {"name": "acc_wheel3", "kind": "wheel_acc", "corner": 3},
    {"name": "disp_wheel2", "kind": "wheel_disp", "corner": 2},
    {"name": "defl4", "kind": "deflection", "corner": 4},
]


def _config(tmp_path, layout):
    if layout is None:
        return load_config(BASE_CONFIG)
    raw = yaml.safe_load(BASE_CONFIG.read_text())
    raw["layout"] = layout
    path = tmp_path / "layout.yaml"
    path.write_text(yaml.safe_dump(raw))
    return load_config(path)


@pytest.mark.parametrize("layout", [None, OFF_CORNER], ids=["corners", "off-corner"])
def test_full_car_matches_central_differences(tmp_path, layout):
    """The paper's unknowns (m, Ix, Iy, a1, b1: a1 and b1 also move the sensor points) away from the configured car:
    every channel's derivative is the central difference of the simulated channels to TOL."""
    cfg = _config(tmp_path, layout)
    exp = build_experiment(cfg)
    names = list(cfg.identify.unknowns)
    values = np.array([cfg.vehicle.values()[n] for n in names]) * np.array([1.1, 0.9, 1.05, 0.95, 1.08])
    out, sens = exp.exact_sensitivities(names, values)
    h = 1e-5 * values
    X = central_points(values, h)
    sim = exp.outputs({n: X[:, j] for j, n in enumerate(names)})
    centre = exp.outputs({n: values[j : j + 1] for j, n in enumerate(names)})
    D = values.size
    for family in sim:
        assert np.max(np.abs(out[family] - centre[family][0])) <= 1e-12 * np.max(np.abs(centre[family]))
        fd = (sim[family][:D] - sim[family][D:]) / (2 * h[:, None, None])
        for j in range(D):
            assert np.max(np.abs(sens[family][..., j] - fd[j])) <= TOL * np.max(np.abs(fd[j])), (family, names[j])


def test_bound_from_exact_sensitivities_is_the_central_difference_bound():
    """The bound uses the exact sensitivities when the experiment has them; with them taken away (central
    differences of the batched simulator, the fallback) it agrees to 1e-6."""
    task = build_task(load_config(BASE_CONFIG, ["identify.objective=wls"]))
    exact = task.bound()

    class Plain:  # the experiment without its exact sensitivities: crlb falls back to central differences
        def outputs(self, values):
            return task.experiment.outputs(values)

    plain = cramer_rao(Plain(), task.names, task.truth, task.sigma)
    assert np.allclose(exact.re_sd_percent, plain.re_sd_percent, rtol=1e-6, atol=0)
    assert np.allclose(exact.fisher, plain.fisher, rtol=1e-6, atol=0)


def test_levenberg_marquardt_reaches_the_trust_region_minimum():
    """From the same random start, lsq on the exact linearisation stops within 2 STEP_SD standard deviations (the
    bound's) of scipy's trust region on forward differences, run to 1e-12, in a handful of evaluations."""
    cfg = load_config(BASE_CONFIG, ["identify.algorithm.name=lsq", "identify.objective=wls"])
    task = build_task(cfg)
    sd = task.bound().sd
    problem = task.problem(task.reference(3))
    assert problem.linearised is not None
    x0 = Search(problem=problem, rng=run_streams(cfg.identify.seed, 3).optimizer, budget=1000).start(None)
    exact_run = Search(problem=problem, rng=np.random.default_rng(0), budget=1000)
    x_exact = gauss_newton(exact_run, x0)
    plain = dataclasses.replace(problem, linearised=None)
    plain_run = Search(problem=plain, rng=np.random.default_rng(0), budget=1000)
    polish(plain_run, x0)
    assert np.all(np.abs(x_exact - plain_run.best_x) <= 2 * STEP_SD * sd)
    assert exact_run.evaluations <= 12 < plain_run.evaluations
    result = get_optimizer("lsq").minimize(problem, run_streams(cfg.identify.seed, 3).optimizer, budget=1000)
    assert np.array_equal(result.x, x_exact)


@pytest.mark.parametrize("config", ["quarter_car/lab_rig.yaml", "half_car/pitch_plane.yaml"])
def test_rigs_match_central_differences(config):
    """The quarter and half car (inputs through springs and dampers, accelerations with the hold's slope term): every
    channel's derivative with respect to each unknown is the central difference of the rig's simulation to TOL, the
    bound agrees with the central-difference one, and lsq takes the exact linearisation."""
    from vehid_cli.systems import build_system

    cfg = load_config(ROOT / "configs" / config)
    system = build_system(cfg)
    values = system.box.nominal * (1 + 0.05 * np.cos(np.arange(system.box.nominal.size)))
    out, sens = system.exact_sensitivities(values)
    D = values.size
    h = 1e-5 * np.abs(values)
    sim = system.outputs(central_points(values, h))
    centre = system.outputs(values[None])
    for family in sim:
        assert np.max(np.abs(out[family] - centre[family][0])) <= 1e-12 * np.max(np.abs(centre[family]))
        fd = (sim[family][:D] - sim[family][D:]) / (2 * h[:, None, None])
        for j in range(D):
            scale = np.max(np.abs(fd[j]))
            assert np.max(np.abs(sens[family][..., j] - fd[j])) <= TOL * scale, (family, system.names[j])
    F_exact = system.information(values)
    plain = dataclasses.replace(system.rigs[0], u=system.rigs[0].u[None])  # a batch of inputs: no exact path
    system.rigs = [plain]
    F_plain = system.information(values)
    scale = np.sqrt(np.outer(np.diag(F_plain), np.diag(F_plain)))  # each element against its correlation's scale
    assert np.all(np.abs(F_exact - F_plain) <= TOL * scale)
    assert system.problem(system.reference(0)).linearised is not None


def test_blocks_carry_the_states():
    """The record in blocks (the modal states carried from one to the next) gives the one-block numbers to round-off,
    whatever the block's size (one that divides the record, one that leaves a single last sample, one longer)."""
    rng = np.random.default_rng(2)
    ns, nu, ny, n, dt = 6, 3, 4, 1001, 1e-3
    parts = _random_parts(rng, ns, nu, ny)
    u = rng.normal(size=(n, nu))
    mats, derivs = _generic(np.array([0.3, 0.7]), parts)
    args = (
        *(M[None] for M in mats[:2]),
        mats[2][None],
        u,
        dt,
        mats[3][None],
        mats[4][None],
        *(d[None] for d in derivs),
    )
    Y, dY, _ = linear_sensitivities(*args, block=n)
    for block in (2, 7, 100, 1000, 4096):
        Yb, dYb, _ = linear_sensitivities(*args, block=block)
        assert np.max(np.abs(Yb - Y)) <= 1e-12 * np.max(np.abs(Y))
        assert np.max(np.abs(dYb - dY)) <= 1e-12 * np.max(np.abs(dY))
