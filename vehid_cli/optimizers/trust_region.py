"""Bounded trust-region reflective least squares: scipy's `least_squares(method='trf')` with the exact (SVD)
trust-region solver and the plain squared loss, ported operation for operation.

Why a port and not the call: importing scipy.optimize (with the scipy.special, linalg and sparse it pulls in) cost
about 0.3 s of every `vehid diagnose` and `vehid identify` start-up, a sixth of a 3 s diagnosis (issue 26), for the
one solver these commands use. The steps are scipy 1.17's (`scipy/optimize/_lsq/trf.py` and `common.py`, BSD-3-Clause,
Copyright (c) 2001-2002 Enthought, Inc. and 2003-2024 SciPy Developers), the same numpy operations in the same order:
with numpy's SVD (LAPACK's gesdd, as scipy.linalg's) the iterates are scipy's bit for bit (tests/test_trust_region.py
runs both). One change: where a step meets the stop tests, scipy still asks for the Jacobian at its point (D
simulations of a forward difference) and never uses it; this does not ask. The final point is the same.
"""

from __future__ import annotations

from collections.abc import Callable
from math import copysign

import numpy as np
from numpy.linalg import norm
from numpy.typing import NDArray

EPS = np.finfo(float).eps


def least_squares(
    fun: Callable[[NDArray], NDArray],
    jac: Callable[[NDArray], NDArray],
    x0: NDArray,
    lb: NDArray,
    ub: NDArray,
    x_scale: NDArray,
    tol: float,
    max_nfev: int | None = None,
) -> NDArray:
    """min 0.5 |fun(x)|² over lb <= x <= ub from x0 (moved strictly inside), the Jacobian from `jac` (x -> (R, D)),
    x scaled by `x_scale` (D,), ftol = xtol = gtol = tol, at most `max_nfev` residuals (100 D by default): the point
    scipy's ``least_squares(fun, x0, jac, (lb, ub), 'trf', x_scale=x_scale, ftol=tol, xtol=tol, gtol=tol,
    max_nfev=max_nfev)`` returns."""
    x0 = np.atleast_1d(np.asarray(x0, dtype=float))
    lb, ub = np.asarray(lb, dtype=float), np.asarray(ub, dtype=float)
    if lb.shape != x0.shape or ub.shape != x0.shape:
        raise ValueError("Inconsistent shapes between bounds and `x0`.")
    if np.any(lb >= ub):
        raise ValueError("Each lower bound must be strictly less than each upper bound.")
    if not in_bounds(x0, lb, ub):
        raise ValueError("Initial guess is outside of provided bounds")
    x_scale = np.asarray(x_scale, dtype=float) * np.ones_like(x0)
    if not np.all(np.isfinite(x_scale)) or np.any(x_scale <= 0):
        raise ValueError("`x_scale` must contain only positive finite numbers.")
    x0 = make_strictly_feasible(x0, lb, ub)
    f0 = np.atleast_1d(fun(x0))
    if not np.all(np.isfinite(f0)):
        raise ValueError("Residuals are not finite in the initial point.")
    J0 = np.atleast_2d(jac(x0))
    if J0.shape != (f0.size, x0.size):
        raise ValueError(f"`jac` returned shape {J0.shape}, expected {(f0.size, x0.size)}")
    return trf_bounds(fun, jac, x0, f0, J0, lb, ub, tol, tol, tol, max_nfev, x_scale)


def trf_bounds(fun, jac, x0, f0, J0, lb, ub, ftol, xtol, gtol, max_nfev, x_scale) -> NDArray:  # noqa: PLR0913
    """scipy's `trf_bounds` (tr_solver 'exact', no loss function): the final x from x0 strictly inside the box, its
    residual f0 and Jacobian J0 there. `jac(x)` is asked only at an accepted point, the one `fun` saw last."""
    x, f, J = x0.copy(), f0, J0
    nfev = 1
    m, n = J.shape
    cost = 0.5 * np.dot(f, f)
    g = J.T.dot(f)
    scale, scale_inv = x_scale, 1 / x_scale
    v, dv = CL_scaling_vector(x, g, lb, ub)
    v[dv != 0] *= scale_inv[dv != 0]
    Delta = norm(x0 * scale_inv / v**0.5)
    if Delta == 0:
        Delta = 1.0
    f_augmented = np.zeros(m + n)
    J_augmented = np.empty((m + n, n))
    max_nfev = x0.size * 100 if max_nfev is None else max_nfev
    alpha = 0.0  # the Levenberg-Marquardt parameter
    termination_status = None
    while True:
        v, dv = CL_scaling_vector(x, g, lb, ub)
        g_norm = norm(g * v, ord=np.inf)
        if g_norm < gtol:
            termination_status = 1
        if termination_status is not None or nfev == max_nfev:
            break
        # the step in "hat" variables: x_scale first, then Coleman-Li's scaling
        v[dv != 0] *= scale_inv[dv != 0]
        d = v**0.5 * scale
        diag_h = g * dv * scale
        g_h = d * g
        f_augmented[:m] = f
        J_augmented[:m] = J * d
        J_h = J_augmented[:m]  # a view
        J_augmented[m:] = np.diag(diag_h**0.5)
        U, s, V = _svd(J_augmented)
        V = V.T
        uf = U.T.dot(f_augmented)
        theta = max(0.995, 1 - g_norm)  # how far a step stays back from the bounds
        actual_reduction = -1
        while actual_reduction <= 0 and nfev < max_nfev:
            p_h, alpha, _ = solve_lsq_trust_region(n, m, uf, s, V, Delta, initial_alpha=alpha)
            p = d * p_h
            step, step_h, predicted_reduction = select_step(x, J_h, diag_h, g_h, p, p_h, d, Delta, lb, ub, theta)
            x_new = make_strictly_feasible(x + step, lb, ub, rstep=0)
            f_new = np.atleast_1d(fun(x_new))
            nfev += 1
            step_h_norm = norm(step_h)
            if not np.all(np.isfinite(f_new)):
                Delta = 0.25 * step_h_norm
                continue
            cost_new = 0.5 * np.dot(f_new, f_new)
            actual_reduction = cost - cost_new
            Delta_new, ratio = update_tr_radius(
                Delta, actual_reduction, predicted_reduction, step_h_norm, step_h_norm > 0.95 * Delta
            )
            termination_status = check_termination(actual_reduction, cost, norm(step), norm(x), ratio, ftol, xtol)
            if termination_status is not None:
                break
            alpha *= Delta / Delta_new
            Delta = Delta_new
        if actual_reduction > 0:
            x, f, cost = x_new, f_new, cost_new
            if termination_status is not None:  # scipy asks for the Jacobian here, then stops without using it
                break
            J = np.atleast_2d(jac(x))
            g = J.T.dot(f)
    return x


def _svd(A: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """The thin SVD as scipy.linalg.svd gives it: LAPACK's gesdd (numpy's too), U and V' in Fortran order (the order
    decides how BLAS sums the products with them, so the steps' last bits), a non-finite matrix refused with this
    ValueError."""
    if not np.all(np.isfinite(A)):
        raise ValueError("array must not contain infs or NaNs")
    U, s, Vt = np.linalg.svd(A, full_matrices=False)
    return np.asfortranarray(U), s, np.asfortranarray(Vt)


def select_step(x, J_h, diag_h, g_h, p, p_h, d, Delta, lb, ub, theta):  # noqa: PLR0913
    """The best of the trust-region step (cut back inside the box), its reflection off the bound it hits and the
    scaled anti-gradient: (step, step in hat variables, the predicted reduction)."""
    if in_bounds(x + p, lb, ub):
        p_value = evaluate_quadratic(J_h, g_h, p_h, diag=diag_h)
        return p, p_h, -p_value
    p_stride, hits = step_size_to_bound(x, p, lb, ub)
    r_h = np.copy(p_h)  # the reflected direction
    r_h[hits.astype(bool)] *= -1
    r = d * r_h
    p *= p_stride  # the step cut at the bound
    p_h *= p_stride
    x_on_bound = x + p
    _, to_tr = intersect_trust_region(p_h, r_h, Delta)
    to_bound, _ = step_size_to_bound(x_on_bound, r, lb, ub)
    r_stride = min(to_bound, to_tr)
    if r_stride > 0:
        r_stride_l = (1 - theta) * p_stride / r_stride
        r_stride_u = theta * to_bound if r_stride == to_bound else to_tr
    else:
        r_stride_l, r_stride_u = 0, -1
    if r_stride_l <= r_stride_u:
        a, b, c = build_quadratic_1d(J_h, g_h, r_h, s0=p_h, diag=diag_h)
        r_stride, r_value = minimize_quadratic_1d(a, b, r_stride_l, r_stride_u, c=c)
        r_h *= r_stride
        r_h += p_h
        r = r_h * d
    else:
        r_value = np.inf
    p *= theta  # strictly inside
    p_h *= theta
    p_value = evaluate_quadratic(J_h, g_h, p_h, diag=diag_h)
    ag_h = -g_h
    ag = d * ag_h
    to_tr = Delta / norm(ag_h)
    to_bound, _ = step_size_to_bound(x, ag, lb, ub)
    ag_stride = theta * to_bound if to_bound < to_tr else to_tr
    a, b = build_quadratic_1d(J_h, g_h, ag_h, diag=diag_h)
    ag_stride, ag_value = minimize_quadratic_1d(a, b, 0, ag_stride)
    ag_h *= ag_stride
    ag *= ag_stride
    if p_value < r_value and p_value < ag_value:
        return p, p_h, -p_value
    if r_value < p_value and r_value < ag_value:
        return r, r_h, -r_value
    return ag, ag_h, -ag_value


def intersect_trust_region(x, s, Delta):
    """The two t with |x + t s| = Delta (x inside the region), the smaller first."""
    a = np.dot(s, s)
    if a == 0:
        raise ValueError("`s` is zero.")
    b = np.dot(x, s)
    c = np.dot(x, x) - Delta**2
    if c > 0:
        raise ValueError("`x` is not within the trust region.")
    d = np.sqrt(b * b - a * c)  # the root of a quarter of the discriminant
    q = -(b + copysign(d, b))  # without loss of significance (Numerical Recipes)
    t1, t2 = q / a, c / q
    return (t1, t2) if t1 < t2 else (t2, t1)


def solve_lsq_trust_region(n, m, uf, s, V, Delta, initial_alpha=None, rtol=0.01, max_iter=10):
    """The step of min |J p + f|² subject to |p| <= Delta from J's SVD (U' f = uf, s, V), by Moré's iteration on the
    Levenberg-Marquardt parameter alpha: (p, alpha, iterations)."""

    def phi_and_derivative(alpha, suf, s, Delta):
        denom = s**2 + alpha
        p_norm = norm(suf / denom)
        return p_norm - Delta, -np.sum(suf**2 / denom**3) / p_norm

    suf = s * uf
    full_rank = s[-1] > EPS * m * s[0] if m >= n else False
    if full_rank:  # the Gauss-Newton step, when it is inside
        p = -V.dot(uf / s)
        if norm(p) <= Delta:
            return p, 0.0, 0
    alpha_upper = norm(suf) / Delta
    if full_rank:
        phi, phi_prime = phi_and_derivative(0.0, suf, s, Delta)
        alpha_lower = -phi / phi_prime
    else:
        alpha_lower = 0.0
    if initial_alpha is None or not full_rank and initial_alpha == 0:
        alpha = max(0.001 * alpha_upper, (alpha_lower * alpha_upper) ** 0.5)
    else:
        alpha = initial_alpha
    for it in range(max_iter):  # noqa: B007 - its count is returned
        if alpha < alpha_lower or alpha > alpha_upper:
            alpha = max(0.001 * alpha_upper, (alpha_lower * alpha_upper) ** 0.5)
        phi, phi_prime = phi_and_derivative(alpha, suf, s, Delta)
        if phi < 0:
            alpha_upper = alpha
        ratio = phi / phi_prime
        alpha_lower = max(alpha_lower, alpha - ratio)
        alpha -= (phi + Delta) * ratio / Delta
        if np.abs(phi) < rtol * Delta:
            break
    p = -V.dot(suf / (s**2 + alpha))
    p *= Delta / norm(p)  # on the region's edge exactly (it is only slightly moved)
    return p, alpha, it + 1


def update_tr_radius(Delta, actual_reduction, predicted_reduction, step_norm, bound_hit):
    """The next trust radius from the step's actual against its predicted reduction: (Delta, their ratio)."""
    if predicted_reduction > 0:
        ratio = actual_reduction / predicted_reduction
    elif predicted_reduction == actual_reduction == 0:
        ratio = 1
    else:
        ratio = 0
    if ratio < 0.25:
        Delta = 0.25 * step_norm
    elif ratio > 0.75 and bound_hit:
        Delta *= 2.0
    return Delta, ratio


def build_quadratic_1d(J, g, s, diag=None, s0=None):
    """The quadratic model 0.5 |J x|² + g'x (+ 0.5 x' diag x) along x = s0 + t s: its coefficients (a, b[, c])."""
    v = J.dot(s)
    a = np.dot(v, v)
    if diag is not None:
        a += np.dot(s * diag, s)
    a *= 0.5
    b = np.dot(g, s)
    if s0 is None:
        return a, b
    u = J.dot(s0)
    b += np.dot(u, v)
    c = 0.5 * np.dot(u, u) + np.dot(g, s0)
    if diag is not None:
        b += np.dot(s0 * diag, s)
        c += 0.5 * np.dot(s0 * diag, s0)
    return a, b, c


def minimize_quadratic_1d(a, b, lb, ub, c=0):
    """The minimum of a t² + b t + c over lb <= t <= ub: (t, value)."""
    t = [lb, ub]
    if a != 0:
        extremum = -0.5 * b / a
        if lb < extremum < ub:
            t.append(extremum)
    t = np.asarray(t)
    y = t * (a * t + b) + c
    i = np.argmin(y)
    return t[i], y[i]


def evaluate_quadratic(J, g, s, diag=None):
    """0.5 |J s|² + g's (+ 0.5 s' diag s) for one step s."""
    Js = J.dot(s)
    q = np.dot(Js, Js)
    if diag is not None:
        q += np.dot(s * diag, s)
    return 0.5 * q + np.dot(s, g)


def in_bounds(x, lb, ub) -> bool:
    return np.all((x >= lb) & (x <= ub))


def step_size_to_bound(x, s, lb, ub):
    """The smallest t > 0 at which x + t s reaches a bound, and which bounds it reaches then (-1, 0, 1 by s' sign)."""
    non_zero = np.nonzero(s)
    s_non_zero = s[non_zero]
    steps = np.empty_like(x)
    steps.fill(np.inf)
    with np.errstate(over="ignore"):
        steps[non_zero] = np.maximum((lb - x)[non_zero] / s_non_zero, (ub - x)[non_zero] / s_non_zero)
    min_step = np.min(steps)
    return min_step, np.equal(steps, min_step) * np.sign(s).astype(int)


def find_active_constraints(x, lb, ub, rtol=1e-10) -> NDArray:
    """-1 where x is at its lower bound (within rtol, relative), 1 at the upper, else 0."""
    active = np.zeros_like(x, dtype=int)
    if rtol == 0:
        active[x <= lb] = -1
        active[x >= ub] = 1
        return active
    lower_dist, upper_dist = x - lb, ub - x
    lower_threshold = rtol * np.maximum(1, np.abs(lb))
    upper_threshold = rtol * np.maximum(1, np.abs(ub))
    active[np.isfinite(lb) & (lower_dist <= np.minimum(upper_dist, lower_threshold))] = -1
    active[np.isfinite(ub) & (upper_dist <= np.minimum(lower_dist, upper_threshold))] = 1
    return active


def make_strictly_feasible(x: NDArray, lb: NDArray, ub: NDArray, rstep: float = 1e-10) -> NDArray:
    """x with the coordinates at (or within rstep of) a bound moved inside it: by rstep relative, or (rstep = 0) to
    the next float; a box too tight for that gets its midpoint."""
    x_new = x.copy()
    active = find_active_constraints(x, lb, ub, rstep)
    lower_mask, upper_mask = np.equal(active, -1), np.equal(active, 1)
    if rstep == 0:
        x_new[lower_mask] = np.nextafter(lb[lower_mask], ub[lower_mask])
        x_new[upper_mask] = np.nextafter(ub[upper_mask], lb[upper_mask])
    else:
        x_new[lower_mask] = lb[lower_mask] + rstep * np.maximum(1, np.abs(lb[lower_mask]))
        x_new[upper_mask] = ub[upper_mask] - rstep * np.maximum(1, np.abs(ub[upper_mask]))
    tight_bounds = (x_new < lb) | (x_new > ub)
    x_new[tight_bounds] = 0.5 * (lb[tight_bounds] + ub[tight_bounds])
    return x_new


def CL_scaling_vector(x, g, lb, ub):  # noqa: N802 - Coleman and Li's name
    """Coleman-Li's scaling v (the distance to the bound the anti-gradient points at, else 1) and its derivative."""
    v = np.ones_like(x)
    dv = np.zeros_like(x)
    mask = (g < 0) & np.isfinite(ub)
    v[mask] = ub[mask] - x[mask]
    dv[mask] = -1
    mask = (g > 0) & np.isfinite(lb)
    v[mask] = x[mask] - lb[mask]
    dv[mask] = 1
    return v, dv


def check_termination(dF, F, dx_norm, x_norm, ratio, ftol, xtol):
    """scipy's status of a step: 2 the cost's fall below ftol, 3 the step below xtol, 4 both, None neither."""
    ftol_satisfied = dF < ftol * F and ratio > 0.25
    xtol_satisfied = dx_norm < xtol * (xtol + x_norm)
    if ftol_satisfied and xtol_satisfied:
        return 4
    if ftol_satisfied:
        return 2
    if xtol_satisfied:
        return 3
    return None
