"""The non-parametric estimate of a missing strut force (diagnose/unexplained.py) against closed-form truths:
15 % more front damping (h = 0.15 cf v), a progressive spring (g = k3 d³), and nothing (linear data)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from tests.conftest import BASE_CONFIG, ROOT, read_png
from vehid_cli.config import load_config
from vehid_cli.diagnose.attribution import lsq_fit
from vehid_cli.diagnose.holdout import holdout_blocks
from vehid_cli.diagnose.linear_response import car_at, responses, responses_blocks
from vehid_cli.diagnose.psplines import basis as _basis
from vehid_cli.diagnose.shapes import SHAPES, _shape_columns, resemblance
from vehid_cli.diagnose.unexplained import Unexplained, estimate_unexplained
from vehid_cli.identify import experiment
from vehid_cli.identify.experiment import Experiment
from vehid_cli.identify.task import build_task
from vehid_cli.report.diagnose_plots import plot_unexplained

NOISE = ["identify.objective=wls", "noise.level=0.03", "identify.truth=config"]
CF = 2800.0  # configured front damping [N s/m]
K3 = {"front": 2e7, "rear": 3e7}  # configs/effects/progressive_spring.yaml [N/m³]
CANDIDATES = [
    "asymmetric_damping", "coulomb_friction", "progressive_spring", "tyre_damping", "hysteresis", "gas_spring",
    "backlash", "damper_lag", "parameter:kf", "parameter:kr", "parameter:cf", "parameter:cr",
]  # fmt: skip


def fitting_task(truth_task, overrides=()):
    """The declared linear car on the same road, weighted by the data's noise sigma (as a measured run is)."""
    nominal = build_task(load_config(BASE_CONFIG, [*NOISE, *overrides]))
    return dataclasses.replace(nominal, sigma=truth_task.sigma)


def inside(curve, truth) -> float:
    """Fraction of the curve's grid where `truth` [N] lies within the 95 % band."""
    return float(np.mean((truth >= curve.band[0]) & (truth <= curve.band[1])))


@pytest.fixture(scope="module")
def damping():
    truth = build_task(load_config(BASE_CONFIG, [*NOISE, f"vehicle.cf={1.15 * CF}"]))
    task = fitting_task(truth)
    ref = truth.reference(0)
    return task, ref, estimate_unexplained(task, ref, task.names, task.nominal)


def force_inputs(damping, offsets: bool, seed: int):
    """The damping case's fitting task (offsets profiled or not), its objective, its linear car and six random input
    histories U (n, 4, 6) of ~100 N, with the generator that drew them (for the kept entries' draw after)."""
    task = dataclasses.replace(damping[0], offsets=offsets)
    exp = task.experiment
    rng = np.random.default_rng(seed)
    U = rng.standard_normal((exp.t.size, 4, 6)) * 100.0
    return task, task.objective(damping[1]), car_at(exp, {}, exp.dt), U, rng


@pytest.fixture(scope="module")
def spring():
    truth = build_task(load_config(ROOT / "configs" / "effects" / "progressive_spring.yaml", NOISE))
    task = fitting_task(truth)
    ref = truth.reference(0)
    keep = ~np.tile(np.repeat(holdout_blocks(task.experiment.t.size), 4), len(task.families))
    return task, ref, keep


# ------------------------------------------------------------------------------------------ closed-form truths


def test_more_front_damping_is_found_as_linear_damping_at_the_front(damping):
    _, _, u = damping
    h = u.front.h
    true = 0.15 * CF * h.grid
    assert inside(h, true) >= 0.9
    assert h.resembles.best == "linear_damping"
    assert h.resembles.amplitude["linear_damping"] == pytest.approx(0.15 * CF, rel=0.05)
    assert h.significant and u.p_value < 1e-9
    assert u.resembles == "linear_damping"
    assert u.acts_on["axle"] == "front" and u.acts_on["variable"] == "velocity"
    # nothing elsewhere: the rear curves and the front spring curve hold zero
    for curve in (u.front.g, u.rear.g, u.rear.h):
        assert inside(curve, np.zeros_like(curve.grid)) >= 0.9
        assert not curve.significant
    # the estimate explains the residual down to the noise
    assert u.chi2_before > 3.0
    assert u.chi2_after == pytest.approx(1.0, abs=0.03)
    assert 3.0 <= u.edf < 20.0


def test_progressive_spring_is_found_as_cubic_stiffening(spring):
    task, ref, keep = spring
    # the declared linear car fitted to the kept data first: the unknowns absorb part of the force
    fit = lsq_fit(task.problem(ref), task.nominal, 80)
    u = estimate_unexplained(task, ref, task.names, fit.x, keep)
    assert u.samples == int(keep.sum())
    for axle in (u.front, u.rear):
        g = axle.g
        assert inside(g, K3[axle.axle] * g.grid**3) >= 0.9
        assert g.resembles.best == "progressive_spring"
        assert g.resembles.amplitude["progressive_spring"] == pytest.approx(K3[axle.axle], rel=0.1)
        assert g.resembles.r2["progressive_spring"] > g.resembles.r2["linear_stiffness"]
        assert inside(axle.h, np.zeros_like(axle.h.grid)) >= 0.9
    assert u.resembles == "progressive_spring"
    assert u.p_value < 1e-9 and u.chi2_after < 1.05 < 2.0 < u.chi2_before
    # the joint re-fit moves the unknowns back towards the true car (the configured m, Ix, Iy, a1, b1)
    assert np.all(np.abs(fit.x + u.dx - task.nominal) <= np.abs(fit.x - task.nominal) + 1e-9 * task.nominal)
    assert u.points_to[0] == "progressive_spring"


def test_linear_data_leave_nothing():
    task = build_task(load_config(BASE_CONFIG, NOISE))
    u = estimate_unexplained(task, task.reference(1), task.names, task.nominal)
    assert u.p_value > 0.05
    assert u.chi2_after == pytest.approx(u.chi2_before, abs=0.01)
    for axle in (u.front, u.rear):
        for curve in (axle.g, axle.h):
            assert inside(curve, np.zeros_like(curve.grid)) >= 0.9
            assert not curve.significant
    assert u.points_to == ()  # nothing significant: it points to nothing


def test_an_augmented_task_with_an_effect_unknown(damping):
    """The loop's tasks carry effect unknowns (and run through the compiled kernel): the estimate still works
    there, the effect's parameter re-fitted inside its box beside the force."""
    task, ref, _ = damping
    rk4 = dataclasses.replace(build_task(load_config(BASE_CONFIG, [*NOISE, "simulation.integrator=rk4"])),
                              sigma=task.sigma)  # fmt: skip
    aug = rk4.with_unknowns(["coulomb_friction.Fc_f"], limits={"coulomb_friction.Fc_f": (0.0, 2000.0)})
    x = np.r_[task.nominal, 0.0]
    u = estimate_unexplained(aug, ref, aug.names, x)
    assert u.names == aug.names and u.dx.shape == (6,)
    assert aug.lower[-1] <= x[-1] + u.dx[-1] <= aug.upper[-1]
    assert u.front.h.resembles.best == "linear_damping"
    assert u.front.h.resembles.amplitude["linear_damping"] == pytest.approx(0.15 * CF, rel=0.05)


# ------------------------------------------------------------------------------------------ API, speed, plot


def test_json_candidates_and_plot(damping, tmp_path):
    _, _, u = damping
    doc = json.loads(json.dumps(u.to_json(), allow_nan=False))
    assert set(doc) >= {"axles", "chi2_before", "chi2_after", "edf", "p_value", "peak_force_N", "acts_on", "resembles"}
    front = doc["axles"]["front"]
    assert front["acts_on"] == "velocity" and front["velocity"]["resembles"]["best"] == "linear_damping"
    assert len(front["velocity"]["force_N"]) == len(front["velocity"]["grid_m_s"]) == 41
    assert doc["peak_force_N"] == pytest.approx(0.15 * CF * max(abs(u.front.h.grid)), rel=0.05)
    assert doc["points_to"] == list(u.points_to) and doc["points_to"][0] == "parameter:cf"
    assert set(u.points_to) <= set(CANDIDATES)
    path = plot_unexplained(u, tmp_path / "unexplained.png")
    assert path == tmp_path / "unexplained.png"
    read_png(path)


def test_keep_must_match_the_residual_layout(damping):
    task, ref, _ = damping
    with pytest.raises(ValueError, match="keep must have 24000"):
        estimate_unexplained(task, ref, task.names, task.nominal, np.ones(100, dtype=bool))


# ------------------------------------------------------------------------------------------ building blocks


def test_constrained_basis_vanishes_at_zero_and_leaves_lines_unpenalised():
    rng = np.random.default_rng(0)
    values = np.r_[0.02 * rng.standard_normal(2000), np.linspace(-0.05, 0.08, 50)]
    b = _basis(values, 10)
    assert np.allclose(b(np.array([0.0])), 0.0)
    grid = np.linspace(-0.05, 0.08, 200)
    X = b(grid)
    coef, *_ = np.linalg.lstsq(X, 3.0 * grid, rcond=None)  # a line through 0 is in the space ...
    assert np.allclose(X @ coef, 3.0 * grid, atol=1e-10)
    assert coef @ b.P @ coef == pytest.approx(0.0, abs=1e-8 * (coef @ coef))  # ... and costs no roughness
    cubic, *_ = np.linalg.lstsq(X, grid**3, rcond=None)
    assert cubic @ b.P @ cubic > 0


@pytest.mark.parametrize("variable", ["deflection", "velocity"])
def test_each_library_shape_resembles_itself(variable):
    x = np.linspace(-0.04, 0.03, 41) if variable == "deflection" else np.linspace(-0.8, 1.0, 41)
    se = np.ones_like(x)
    for name in SHAPES[variable]:
        curve, _sign, _ = _shape_columns(variable, x)[name][-1]
        assert resemblance(variable, x, 250.0 * curve, se).best == name


def test_points_to_follows_the_dominant_curve(damping):
    _, _, u = damping
    assert isinstance(u, Unexplained)
    assert u.points_to[0] == "parameter:cf"
    assert "parameter:cr" not in u.points_to  # the rear shows nothing
    assert "of the library's terms its shape points to parameter:cf" in u.summary()


@pytest.mark.parametrize("block", [2, 5, 256, 2999])
def test_responses_in_blocks_equal_one_recursion(damping, block):
    """The linear car's states driven by many strut-force histories, made a block of time at a time with the
    recursion carried over (what the force's columns and the trajectory's correction use), are those of one
    recursion over the record, bit for bit (a last block of one sample joins the one before)."""
    task = damping[0]
    exp = task.experiment
    car = car_at(exp, {}, exp.dt)
    rng = np.random.default_rng(3)
    U = rng.standard_normal((exp.t.size, 4, 6)) * 100.0
    whole = responses(car, U)
    parts = list(responses_blocks(car, U, block))
    assert all(s.shape[0] >= 2 for _, s in parts)
    np.testing.assert_array_equal(np.concatenate([s for _, s in parts]), whole)
    assert [k0 for k0, _ in parts] == list(np.cumsum([0] + [s.shape[0] for _, s in parts[:-1]]))


def test_a_record_simulated_in_time_blocks_gives_the_same_estimate(monkeypatch):
    """On a record the experiment simulates in time blocks (6 s on the RK4 kernel, blocked from 2 blocks of 2048 samples
    on: channels and strut trajectories read a block at a time), the estimate is the one from whole simulations, bit
    for bit."""
    monkeypatch.setattr(experiment, "BLOCKED_FROM", 2)
    sets = [*NOISE, "simulation.integrator=rk4", "simulation.duration=6", "road.bump=null", "road.random.iso_class=C"]
    truth = build_task(load_config(ROOT / "configs" / "effects" / "hysteresis.yaml", sets))
    task = dataclasses.replace(build_task(load_config(BASE_CONFIG, sets)), sigma=truth.sigma)
    ref = truth.reference(0)
    assert task.experiment.blocked(None)
    blocked = estimate_unexplained(task, ref, task.names, task.nominal, iterations=2)
    monkeypatch.setattr(Experiment, "blocked", lambda self, values=None: False)
    assert not task.experiment.blocked(None)
    whole = estimate_unexplained(task, ref, task.names, task.nominal, iterations=2)
    assert blocked.p_value < 1e-6  # the hysteresis is seen
    assert json.dumps(blocked.to_json()) == json.dumps(whole.to_json())


@pytest.mark.parametrize("offsets", [False, True])
def test_the_kept_response_columns_are_written_without_the_whole_matrix_bit_for_bit(damping, offsets):
    """response_columns with `keep` (the missing force's fit matrix [J | S[keep]]): the kept rows of the whole (R, K)
    responses, bit for bit, in the columns after the caller's; written block by block without the whole matrix when
    no offsets are profiled, made whole and copied when they are (each channel's mean over every sample first)."""
    from vehid_cli.diagnose.linear_response import response_columns

    task, objective, car, U, rng = force_inputs(damping, offsets, seed=4)
    whole = response_columns(objective, car, U, task.sigma)
    keep = rng.random(whole.shape[0]) < 0.7
    A = response_columns(objective, car, U, task.sigma, keep, 3)
    assert A.shape == (keep.sum(), 9)
    np.testing.assert_array_equal(A[:, 3:], whole[keep])
