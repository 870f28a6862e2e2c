"""A long record's screening window (diagnose/window.py): the window's model and residuals are the whole record's
first samples, bit for bit (the car starts at rest and the integrators step forward), so a fit or test on the window
is the same fit or test on fewer data; records of a test case's length are never windowed."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vehid_cli.config import load_config
from vehid_cli.diagnose.window import LONG_RECORD, SCREEN_SAMPLES, is_long, window_task
from vehid_cli.identify.task import build_task
from vehid_cli.systems.vehicle.diagnosis import prepare_config

ROOT = Path(__file__).resolve().parents[1]
HYSTERESIS = ROOT / "configs" / "effects" / "hysteresis.yaml"
LONG = ["road.bump=null", "road.random.iso_class=C", "identify.objective=wls"]


def test_window_residuals_are_the_records_first_samples():
    seconds = 1.2 * LONG_RECORD / 1000.0  # just long enough to be windowed at 1 kHz
    cfg = prepare_config(load_config(HYSTERESIS, [*LONG, f"simulation.duration={seconds}"]))
    task = build_task(cfg)
    assert is_long(task) and task.experiment.t.size > LONG_RECORD
    head = window_task(task)
    n = SCREEN_SAMPLES
    assert head.experiment.t.size == n and np.array_equal(head.experiment.road, task.experiment.road[:n])
    ref = task.reference(0)
    wref = {f: v[:n] for f, v in ref.items()}
    rng = np.random.default_rng(5)
    X = task.nominal * rng.uniform(0.9, 1.1, size=(3, task.dim))  # three cars off the configured one
    _, r_full = task.problem(ref).residuals(X)
    _, r_head = head.problem(wref).residuals(X)
    at_full = at_head = 0
    for family in task.families:  # each family's block is time-major: its first n samples come first
        k = ref[family].shape[1]
        assert np.array_equal(r_head[:, at_head : at_head + n * k], r_full[:, at_full : at_full + n * k])
        at_full, at_head = at_full + ref[family].shape[0] * k, at_head + n * k
    assert at_head == r_head.shape[1] and at_full == r_full.shape[1]


def test_a_test_length_record_is_not_windowed():
    cfg = prepare_config(load_config(HYSTERESIS, ["identify.objective=wls"]))
    task = build_task(cfg)
    assert task.experiment.t.size <= LONG_RECORD and not is_long(task)


def test_the_windows_cars_are_simulated_a_few_at_a_time_with_the_same_numbers():
    """The window simulates at most WINDOW_CHUNK_BYTES of cars' full responses at once (a candidate fit's Jacobian
    batch of 13 cars in chunks of 4, two fits in threads at a time): each car's costs and residuals equal those of
    the whole batch simulated at once, bit for bit."""
    import dataclasses

    from vehid_cli.diagnose.window import WINDOW_CHUNK_BYTES

    seconds = 1.2 * LONG_RECORD / 1000.0
    cfg = prepare_config(load_config(HYSTERESIS, [*LONG, f"simulation.duration={seconds}"]))
    task = build_task(cfg)
    head = window_task(task)
    exp = head.experiment
    assert exp.chunk_bytes == WINDOW_CHUNK_BYTES and 2 <= exp.cars_per_chunk < 13
    whole = dataclasses.replace(head, experiment=dataclasses.replace(exp, chunk_bytes=2**40))
    assert whole.experiment.cars_per_chunk >= 13
    wref = {f: v[:SCREEN_SAMPLES] for f, v in task.reference(0).items()}
    rng = np.random.default_rng(8)
    X = task.nominal * rng.uniform(0.95, 1.05, size=(13, task.dim))
    costs, r = head.problem(wref).residuals(X)
    costs_whole, r_whole = whole.problem(wref).residuals(X)
    assert np.array_equal(r, r_whole) and np.array_equal(costs, costs_whole)


def test_the_windows_linear_car_is_fitted_on_its_exact_twin():
    """A long record's screening subject offers the window's linear car on the exact integrator (its known
    parameters' candidates and its re-fits by Levenberg–Marquardt: a few evaluations, the window's Jacobian held),
    the same window's first samples; with an effect declared it offers none (the trust region then)."""
    from vehid_cli.systems.vehicle.diagnosis import CarLoop, exact_twin, screening, validation_split

    base = ROOT / "configs" / "gokdag2015" / "base.yaml"
    seconds = 1.2 * LONG_RECORD / 1000.0
    for config, linear in ((base, True), (HYSTERESIS, False)):
        cfg = prepare_config(load_config(config, [*LONG, f"simulation.duration={seconds}", "noise.level=0.03"]))
        task = build_task(cfg)
        ref = task.reference(0)
        split = validation_split(cfg, task, ref, ["run.csv"], None)
        car = CarLoop(task, ref, split, {"limits": {}, "start": {}}, ("run.csv",), twin=exact_twin(task))
        subject, wcar = screening(task, ref, split, car, {}, ("run.csv",))
        assert (subject.linear_for is not None) == linear
        if not linear:
            continue
        exact = subject.linear_for(task.names + ("kf",))
        problem = subject.problem_for(task.names + ("kf",))[0]
        assert exact is not None and exact.linearised is not None  # a window: its Jacobian is held
        x = np.concatenate([task.nominal, [cfg.vehicle.kf * 1.01]])
        cost, r, _ = exact.linearised(x)
        c0, r0 = problem.residuals(x[None, :])
        assert r.size == r0.shape[1] == wcar.task.residual_samples - int((~wcar.split.keep).sum())
        assert abs(cost - c0[0]) < 1e-4 * c0[0]  # the integrators agree to rk4's error at 1 kHz
        assert subject.linear_for(task.names + ("hysteresis.alpha_f",)) is None


def test_single_points_hold_the_newest_vectors_within_their_limits(monkeypatch):
    """The fits' held residual vectors (their validation J read from them): the newest always kept, at most
    MAX_POINTS and MAX_BYTES of them, a point evaluated again moved to the newest, and all of them forgotten by
    clear() (before a long record's missing-force estimate)."""
    from vehid_cli.systems.vehicle.diagnosis import SinglePoints

    monkeypatch.setattr(SinglePoints, "MAX_POINTS", 3)
    monkeypatch.setattr(SinglePoints, "MAX_BYTES", 5 * 800)  # five vectors of 100 doubles
    held = SinglePoints()
    for i in range(5):
        held._put((("kf",), np.array([float(i)]).tobytes()), np.full(100, float(i)))
    assert [held.get(("kf",), np.array([float(i)])) is not None for i in range(5)] == [False, False, True, True, True]
    held._put((("kf",), np.array([2.0]).tobytes()), np.full(100, 2.0))  # 2 again: now the newest, 3 the oldest
    held._put((("kf",), np.array([9.0]).tobytes()), np.full(100, 9.0))
    assert held.get(("kf",), np.array([3.0])) is None and held.get(("kf",), np.array([2.0]))[0] == 2.0
    held._put((("kf",), np.array([7.0]).tobytes()), np.full(10_000, 7.0))  # alone over MAX_BYTES: still kept
    assert held.get(("kf",), np.array([7.0])) is not None and held.get(("kf",), np.array([9.0])) is None
    held.clear()
    assert held.get(("kf",), np.array([7.0])) is None
