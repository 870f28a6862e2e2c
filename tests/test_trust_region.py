"""The ported trust-region least squares (optimizers/trust_region.py) against scipy's own `least_squares(method='trf')`:
the same residuals and Jacobians asked for, at the same points, bit for bit (but the Jacobian scipy asks for at the
point it stops at and does not use), and the same final point, on problems
with the solution inside the box, on a bound, from a start on a bound, with a rank-deficient Jacobian and with trial
steps into a region where the residual is not finite."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import least_squares as scipy_least_squares

from vehid_cli.optimizers import trust_region

T = np.linspace(0.0, 10.0, 400)


def damped_sine(seed: int):
    """A damped sine's residual and Jacobian in (amplitude, decay, frequency, phase), with noise."""
    rng = np.random.default_rng(seed)
    y = 3 * np.exp(-0.3 * T) * np.sin(2 * T + 0.5) + 0.05 * rng.standard_normal(T.size)

    def fun(p):
        return p[0] * np.exp(-p[1] * T) * np.sin(p[2] * T + p[3]) - y

    def jac(p):
        e, s, c = np.exp(-p[1] * T), np.sin(p[2] * T + p[3]), np.cos(p[2] * T + p[3])
        return np.stack([e * s, -T * p[0] * e * s, p[0] * e * c * T, p[0] * e * c], axis=1)

    return fun, jac


def recorded(fun, jac):
    """fun and jac that log each point they are asked at."""
    calls = []

    def f(x):
        calls.append(("f", x.copy()))
        return fun(x)

    def j(x):
        calls.append(("j", x.copy()))
        return jac(x)

    return f, j, calls


def both(fun, jac, x0, lo, hi, tol=1e-12, max_nfev=None):
    """(scipy's final x, its calls), (ours, its calls)."""
    f, j, theirs = recorded(fun, jac)
    ref = scipy_least_squares(f, x0, jac=j, bounds=(lo, hi), method="trf", x_scale=hi - lo, xtol=tol, ftol=tol,
                              gtol=tol, max_nfev=max_nfev)  # fmt: skip
    f, j, ours = recorded(fun, jac)
    x = trust_region.least_squares(f, j, x0, lo, hi, hi - lo, tol, max_nfev)
    return (ref.x, theirs), (x, ours)


def assert_same(a, b):
    """The same points asked for, in the same order, and the same final point; scipy asks once more, for the
    Jacobian at the point where the stop tests are met, which it does not use (trust_region.py does not ask)."""
    (xa, ca), (xb, cb) = a, b
    if len(ca) == len(cb) + 1:
        assert ca[-1][0] == "j" and np.array_equal(ca[-1][1], xa)
        ca = ca[:-1]
    assert [k for k, _ in ca] == [k for k, _ in cb]
    for (_, pa), (_, pb) in zip(ca, cb, strict=True):
        assert np.array_equal(pa, pb)
    assert np.array_equal(xa, xb)


@pytest.mark.parametrize("seed", range(3))
def test_inside_the_box_the_same_steps_bit_for_bit(seed):
    fun, jac = damped_sine(seed)
    lo, hi = np.array([0.0, 0.0, 1.0, -1.0]), np.array([5.0, 1.0, 3.0, 2.0])
    a, b = both(fun, jac, np.array([2.0, 0.5, 1.8, 0.2]), lo, hi)
    assert_same(a, b)
    assert len(a[1]) == len(b[1]) + 1  # it stopped on its tests: one Jacobian fewer
    assert abs(b[0][2] - 2.0) < 0.02  # and a fit: the frequency found


def test_a_solution_on_a_bound_and_a_start_on_one():
    fun, jac = damped_sine(0)
    lo, hi = np.array([0.0, 0.4, 1.0, -1.0]), np.array([5.0, 1.0, 3.0, 2.0])  # the decay's truth 0.3 is outside
    a, b = both(fun, jac, np.array([2.0, 0.4, 1.8, 2.0]), lo, hi)
    assert_same(a, b)
    assert b[0][1] == pytest.approx(0.4, abs=1e-9)


def test_a_rank_deficient_jacobian():
    """Two unknowns that only enter as their sum: the Jacobian has rank 1."""
    y = np.linspace(0, 1, 50) * 3.0

    def fun(p):
        return (p[0] + p[1]) * np.linspace(0, 1, 50) - y

    def jac(p):
        c = np.linspace(0, 1, 50)
        return np.stack([c, c], axis=1)

    a, b = both(fun, jac, np.array([0.2, 0.3]), np.zeros(2), np.full(2, 4.0))
    assert_same(a, b)
    assert b[0].sum() == pytest.approx(3.0, rel=1e-9)


def test_steps_into_a_region_without_a_finite_residual():
    """The residual is NaN beyond a frequency of 2.05: the trust region shrinks and steps again, as scipy's does."""
    fun0, jac0 = damped_sine(1)

    def fun(p):
        r = fun0(p)
        return r if p[2] < 2.05 else np.full_like(r, np.nan)

    a, b = both(fun, jac0, np.array([1.0, 0.1, 1.2, 0.0]), np.array([0.0, 0.0, 1.0, -1.0]),
                np.array([5.0, 1.0, 3.0, 2.0]), max_nfev=40)  # fmt: skip
    assert_same(a, b)
    assert any(k == "f" and p[2] >= 2.05 for k, p in b[1])  # it did step there


def test_bad_input_is_refused_as_scipy_refuses_it():
    fun, jac = damped_sine(0)
    lo, hi = np.zeros(4), np.full(4, 5.0)
    with pytest.raises(ValueError, match="outside of provided bounds"):
        trust_region.least_squares(fun, jac, np.full(4, 6.0), lo, hi, hi - lo, 1e-12)
    with pytest.raises(ValueError, match="not finite in the initial point"):
        trust_region.least_squares(lambda p: np.full(3, np.inf), jac, np.ones(4), lo, hi, hi - lo, 1e-12)
    with pytest.raises(ValueError, match="infs or NaNs"):  # a Jacobian with a NaN: scipy.linalg.svd's refusal
        trust_region.least_squares(fun, lambda p: np.full((T.size, 4), np.nan), np.ones(4), lo, hi, hi - lo, 1e-12)
