"""diagnose/psplines.py's own numerics: the B-splines (partition of unity and reproduction of straight lines, the
independent truths; scipy's BSpline to round-off) and the box-constrained minimiser of the smoothing parameters
(closed-form minima inside and on the box, an ill-conditioned one, and at least as low as scipy's L-BFGS-B on the REML
scores of penalised fits)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.interpolate import BSpline
from scipy.optimize import minimize

from vehid_cli.diagnose import psplines
from vehid_cli.diagnose.psplines import basis, box_minimum, bsplines


def knots(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return basis(rng.standard_normal(400) * rng.uniform(0.01, 2.0), int(rng.integers(3, 14))).t


@pytest.mark.parametrize("seed", range(4))
def test_bsplines_sum_to_one_reproduce_lines_and_match_scipy(seed):
    t = knots(seed)
    nb = t.size - 4
    x = np.r_[t[3], t[-4], np.random.default_rng(seed).uniform(t[3], t[-4], 500), t[4:-4]]  # ends and inner knots
    B = bsplines(x, t)
    np.testing.assert_allclose(B.sum(axis=1), 1.0, rtol=0, atol=1e-15)
    greville = (t[1:-3] + t[2:-2] + t[3:-1]) / 3.0  # sum_j greville_j B_j(x) = x for cubic B-splines
    np.testing.assert_allclose(B @ greville, x, rtol=0, atol=1e-14 * np.abs(t).max())
    np.testing.assert_allclose(B, BSpline.design_matrix(x, t, 3).toarray(), rtol=0, atol=1e-15)
    inner = x[2:502]
    for order in (1, 2):
        D = bsplines(inner, t, derivative=order)
        ref = BSpline(t, np.eye(nb), 3).derivative(order)(inner)
        np.testing.assert_allclose(D, ref, rtol=0, atol=1e-14 * np.abs(ref).max())
        np.testing.assert_allclose(D.sum(axis=1), 0.0, atol=1e-12 * np.abs(ref).max())  # of a constant
    np.testing.assert_allclose(bsplines(inner, t, derivative=1) @ greville, 1.0, rtol=1e-12)  # of x


def test_box_minimum_of_quadratics_inside_and_on_the_box():
    A = np.array([[3.0, 1.0], [1.0, 2.0]])
    centre = np.array([0.3, -0.2])
    x = box_minimum(lambda x: (x - centre) @ A @ (x - centre), np.array([2.0, 2.5]), -1.0, 3.0)
    np.testing.assert_allclose(x, centre, atol=1e-3)
    outside = np.array([-2.0, 1.0])  # by KKT: x0 = -1 (its gradient there pushes out), x1 = 1 - (1/2)(-1 + 2) = 0.5
    x = box_minimum(lambda x: (x - outside) @ A @ (x - outside), np.array([0.5, 0.5]), -1.0, 3.0)
    assert x[0] == -1.0
    np.testing.assert_allclose(x[1], outside[1] - A[1, 0] / A[1, 1] * (x[0] - outside[0]), atol=1e-3)


def test_box_minimum_of_an_ill_conditioned_quadratic():
    """Curvatures 1 and 1000 along rotated axes, from a far start: the minimum to 1e-3."""
    c, s_ = np.cos(0.4), np.sin(0.4)
    R = np.array([[c, -s_], [s_, c]])
    A = R @ np.diag([1.0, 1000.0]) @ R.T
    centre = np.array([0.7, -0.3])
    x = box_minimum(lambda x: (x - centre) @ A @ (x - centre), np.array([-4.0, 4.0]), -5.0, 5.0)
    np.testing.assert_allclose(x, centre, atol=1e-3)


def noisy_curves(seed: int, unpenalised: int = 0):
    """Sums of sines on one to three variables (300 noisy samples) as penalised blocks of 8-knot bases, after
    `unpenalised` constant columns: the fit matrix A, the data r, the blocks and their count k."""
    rng = np.random.default_rng(seed)
    k = 1 + seed % 3
    x = rng.uniform(-1, 1, (300, k))
    bases = [basis(x[:, j], 8) for j in range(k)]
    A = np.hstack([np.ones((300, unpenalised))] + [b(x[:, j]) for j, b in enumerate(bases)])
    r = np.sin(3 * x).sum(axis=1) + 0.1 * rng.standard_normal(300)
    start, blocks = unpenalised, []
    for b in bases:
        blocks.append((slice(start, start + b.size), b.P))
        start += b.size
    return A, r, blocks, k


def recording(monkeypatch) -> dict:
    """What penalised_fit hands box_minimum (the score f, the start x0, the gradient), recorded as it runs."""
    seen = {}

    def record(f, x0, lo, hi, grad=None):
        seen["f"], seen["x0"], seen["grad"] = f, x0.copy(), grad
        return box_minimum(f, x0, lo, hi, grad=grad)

    monkeypatch.setattr(psplines, "box_minimum", record)
    return seen


@pytest.mark.parametrize("seed", range(6))
def test_smoothing_parameters_as_good_as_l_bfgs_b(seed, monkeypatch):
    """The REML (and GCV) scores of penalised fits of noisy curves on one to three penalised blocks: box_minimum's
    smoothing parameters score no worse than scipy's L-BFGS-B (the minimiser it replaces) to 1e-9 of the score."""
    A, r, blocks, k = noisy_curves(seed)
    scores = recording(monkeypatch)
    for criterion in ("reml", "gcv"):
        sol = psplines.penalised_fit(A.T @ A, A.T @ r, float(r @ r), 300, blocks, criterion)
        f = scores["f"]
        ours = f(np.log10(sol.lam))
        res = minimize(f, scores["x0"], method="L-BFGS-B", bounds=[psplines.LOG_LAMBDA] * k, options={"eps": 1e-4})
        assert ours <= min(res.fun, f(scores["x0"])) + 1e-9 * abs(ours)


def test_a_fit_whose_inverse_fails_is_a_failed_fit_not_an_error(monkeypatch):
    """Cholesky can accept an H that LAPACK's inverse then calls singular (the four-post rig's unexplained force hit
    it at a large smoothing parameter): that fit scores inf like one Cholesky refuses, and the search backs away."""
    rng = np.random.default_rng(3)
    x = rng.uniform(-1, 1, 300)
    b = basis(x, 8)
    A = b(x)
    r = np.sin(3 * x) + 0.1 * rng.standard_normal(300)
    inv = np.linalg.inv

    def refusing(a):
        if np.max(np.abs(a)) > 1e4:  # every H of a smoothing parameter above about 1e4 "singular"
            raise np.linalg.LinAlgError("Singular matrix")
        return inv(a)

    monkeypatch.setattr(np.linalg, "inv", refusing)
    sol = psplines.penalised_fit(A.T @ A, A.T @ r, float(r @ r), 300, [(slice(0, b.size), b.P)])
    assert np.all(np.isfinite(sol.coef)) and np.all(sol.lam < 1e4)


@pytest.mark.parametrize("seed", range(4))
def test_reml_gradient_is_the_scores_derivative(seed, monkeypatch):
    """The exact gradient the smoothing parameters' search takes agrees with central differences of the REML score
    (step 1e-5: truncation and round-off about 1e-7 of the gradient) at the optimum found and at random points, on
    one to three penalised blocks beside an unpenalised column."""
    A, r, blocks, k = noisy_curves(seed, unpenalised=1)
    rng = np.random.default_rng(seed)
    seen = recording(monkeypatch)
    sol = psplines.penalised_fit(A.T @ A, A.T @ r, float(r @ r), 300, blocks)
    f, grad = seen["f"], seen["grad"]
    assert grad is not None
    for rho in (np.log10(sol.lam), rng.uniform(-5, 6, k), rng.uniform(-5, 6, k)):
        h = 1e-5
        numeric = np.array([(f(rho + h * e) - f(rho - h * e)) / (2 * h) for e in np.eye(k)])
        assert np.allclose(grad(rho), numeric, rtol=1e-4, atol=1e-4 * max(1.0, np.max(np.abs(numeric))))
