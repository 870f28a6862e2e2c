"""identify/convergence.py: one fit's distance from its least-squares optimum, against the closed-form least-squares
solution of a linear problem, and on the independent simulator's measured run: a global search stopped short is said
to be, the trust region's optimum is not."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import BASE_CONFIG, VEHICLE_DATA, needs_shared, vehid
from vehid_cli.campaign.runner import run_campaign
from vehid_cli.config import load_config
from vehid_cli.identify.convergence import optimum_offset
from vehid_cli.optimizers.base import Problem

RNG = np.random.default_rng(7)
A = RNG.normal(size=(200, 3)) * np.array([1.0, 30.0, 0.01])  # columns of very different scales, as a car's unknowns
B = A @ np.array([2.0, -0.5, 40.0]) + RNG.normal(size=200)


def linear_problem(exact: bool) -> Problem:
    """r(x) = A x - B (unit noise), its sensitivities given (`exact`) or left to forward differences."""

    def residuals(X):
        R = np.atleast_2d(X) @ A.T - B
        return np.mean(R**2, axis=1), R

    def linearised(x):
        r = A @ x - B
        return float(np.mean(r**2)), r, A

    return Problem(np.full(3, -1e3), np.full(3, 1e3), lambda X: residuals(X)[0], residuals,
                   names=("p", "q", "s"), linearised=linearised if exact else None)  # fmt: skip


OPTIMUM = np.linalg.lstsq(A, B, rcond=None)[0]
SD = np.sqrt(np.diag(np.linalg.inv(A.T @ A)))  # the bound's sd of unit-noise residuals


@pytest.mark.parametrize("exact", [True, False])
def test_the_step_is_the_way_to_the_closed_form_optimum(exact):
    off = np.array([3.0, -0.2, 0.1]) * SD  # 3 sd, 0.2 sd, 0.1 sd away from the optimum
    got = optimum_offset(linear_problem(exact), OPTIMUM + off, SD, np.zeros(3, dtype=bool))
    tol = 1e-9 if exact else 1e-4  # forward differences of a linear residual: round-off of the step only
    np.testing.assert_allclose(got.step, -off, rtol=tol, atol=tol * SD.max())
    np.testing.assert_allclose(got.in_sd, [-3.0, 0.2, -0.1], atol=1e-3)
    assert got.far == (0,)  # only p is OFFSET_SD or more away
    text = got.describe({"p": "kg"}, "abc", "f2")
    assert "p by" in text and "kg (3 sd)" in text and "abc stopped" in text and "q by" not in text
    # lsq ends at the least-squares optimum but keeps the point of lowest cost it passed: under f2 (a sum of norms)
    # that may be an earlier one (a 60 s record with kf and cr off: 1.3 sd short in a1), which the objective wls avoids
    lsq = got.describe({}, "lsq", "f2")
    assert "lsq kept the point of lowest f2 cost" in lsq and "identify.objective=wls" in lsq
    assert "kept the point" not in got.describe({}, "lsq", "wls")


def test_a_held_unknown_stays_and_the_others_go_to_their_optimum_with_it_held():
    held = np.array([False, True, False])
    x = OPTIMUM + np.array([1.0, 2.0, -1.0]) * SD
    got = optimum_offset(linear_problem(True), x, SD, held)
    free = ~held
    best = np.linalg.lstsq(A[:, free], B - A[:, held] @ x[held], rcond=None)[0]  # the optimum with q held
    np.testing.assert_allclose(got.step[free], best - x[free], rtol=1e-9)
    assert got.step[1] == 0.0 and np.isnan(got.in_sd[1])


def test_at_the_optimum_nothing_is_said():
    got = optimum_offset(linear_problem(False), OPTIMUM, SD, np.zeros(3, dtype=bool))
    assert np.all(np.abs(got.in_sd) < 1e-3) and got.far == () and got.describe({}, "lsq", "wls") is None
    assert optimum_offset(linear_problem(True), OPTIMUM, SD, np.ones(3, dtype=bool)) is None  # nothing free


@pytest.mark.parametrize("algorithm, stopped_short", [("abc", True), ("ga", True), ("lsq", False)])
def test_one_fit_says_when_its_search_stopped_short_of_the_optimum(algorithm, stopped_short):
    """The paper's ABC and GA (1000 evaluations) on the independent simulator's linear run stop several standard
    deviations from the optimum (Ix 490.8 and 427.7 kg m² for 500, with ± 5-6): the warning names the unknowns and
    how far; lsq ends at the optimum and says nothing of it."""
    data = needs_shared(VEHICLE_DATA / "bump_run_linear.csv")
    cfg = load_config(BASE_CONFIG, ["identify.runs=1", f"identify.algorithm.name={algorithm}"])
    campaign = run_campaign(cfg, data, jobs=1)
    said = [w for w in campaign.warnings if w.startswith("the estimate is not at the least-squares optimum")]
    assert bool(said) is stopped_short, campaign.warnings
    if stopped_short:
        assert "Ix by +" in said[0] and f"where {algorithm} stopped" in said[0]


def test_the_warning_is_handed_on_with_the_campaign_file(tmp_path):
    """`vehid identify` writes the warning into its campaign file and `vehid report` says it again under the table,
    on the terminal and in a report written with -o."""
    data = needs_shared(VEHICLE_DATA / "bump_run_linear.csv")
    target = tmp_path / "abc.h5"
    res = vehid("identify", BASE_CONFIG, "--data", data, "--set", "identify.algorithm.name=abc", "-o", target)
    assert res.returncode == 0, res.stderr
    said = "the estimate is not at the least-squares optimum"
    assert said in res.stdout
    shown = vehid("report", target)
    assert shown.returncode == 0 and said in shown.stdout and "Ix by +" in shown.stdout
    written = tmp_path / "report.txt"
    assert vehid("report", target, "-o", written).returncode == 0 and said in written.read_text()
