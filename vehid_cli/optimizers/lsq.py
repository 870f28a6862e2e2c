"""Trust-region least squares (scipy's 'trf', ported: trust_region.py) on the weighted residual vector, inside the box.

Minimising the sum of squared weighted residuals is the Gaussian maximum-likelihood estimate, which is
what reaches the Cramér–Rao bound. A problem that gives its residuals with their exact Jacobian from one
simulation (`Problem.linearised`: the linear car's sensitivities through the same modal solution) is solved by
Levenberg–Marquardt on them (`gauss_newton`), one evaluation per step, stopping once the step is a negligible
fraction of the estimate's own standard deviation; otherwise the trust-region least squares, whose Jacobian is
a forward difference computed in ONE batched evaluation of the D perturbed points (counted as D evaluations),
reusing the residual at the centre.
A forward-difference Jacobian above LONG_JACOBIAN_BYTES (a long record) is fitted compressed (`compressed.py`):
the same steps on D + 1 rows, without the solver's copies of the (R, D) matrix.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from .base import BudgetExhausted, Optimizer, Search, register
from .compressed import trf_compressed
from .trust_region import least_squares, make_strictly_feasible

JACOBIAN_STEP = 1e-7  # forward-difference step, as a fraction of each parameter's box width
LONG_JACOBIAN_BYTES = 4 * 2**20  # a Jacobian larger than this is fitted compressed (optimizers/compressed.py), or
# from its normal equations summed over the record (`Problem.normal`): above it the solver's copies of the (R, D)
# Jacobian (6 of them, 70 MB for 60 s x 8 channels x 3 unknowns) outweigh the memory of the rest of a fit (issue 26)


def polish(run: Search, x0: NDArray, max_nfev: int | None = None, tol: float = 1e-12) -> NDArray:
    """Least-squares polish from x0 using the run's budget, to relative tolerance `tol` of the cost and the
    step; returns the final point (the run tracks the best)."""
    lo, hi = run.problem.lower, run.problem.upper
    width = hi - lo
    cache: dict[bytes, NDArray] = {}

    def residual(x: NDArray) -> NDArray:
        key = x.tobytes()
        if key not in cache:
            cache.clear()
            cache[key] = run.evaluate_residuals(x[None, :])[0]
        return cache[key]

    def steps(x: NDArray) -> NDArray:
        """The forward differences' step along each unknown at x, inward at the upper bound."""
        h = JACOBIAN_STEP * width
        return np.where(x + h <= hi, h, -h)

    def jacobian_rows(x: NDArray) -> NDArray:
        """(D, R): row j the residual's forward difference by unknown j."""
        r0 = residual(x)
        step = steps(x)
        X = x[None, :] + np.diag(step)
        R = run.evaluate_residuals(X)
        R -= r0[None, :]  # in place: a long record's Jacobian is tens of MB per copy
        R /= step[:, None]
        return R

    def jacobian_gram(x: NDArray) -> NDArray | None:
        """The Gram matrix of [J r] at x, jacobian_rows' J summed without it (Problem.gram), or None."""
        step = steps(x)
        return run.evaluate_gram(np.vstack([x[None, :], x[None, :] + np.diag(step)]), step)

    def jacobian(x: NDArray) -> NDArray:
        return jacobian_rows(x).T

    x0 = np.clip(np.asarray(x0, dtype=float), lo + 1e-12 * width, hi - 1e-12 * width)
    x0 = make_strictly_feasible(x0, lo, hi)
    if residual(x0).size * x0.size * 8 > LONG_JACOBIAN_BYTES:  # a long record: the same steps on D + 1 rows
        gram = jacobian_gram if run.problem.gram is not None else None
        return trf_compressed(residual, jacobian_rows, x0, lo, hi, width, tol, max_nfev, gram=gram)
    return least_squares(residual, jacobian, x0, lo, hi, width, tol, max_nfev)


STEP_SD = 1e-2  # gauss_newton stops when its step is below this many of the estimate's standard deviations
LAST_SD = 5e-2  # ... or takes its step unlinearised and stops when the next one is predicted below this many
MAX_STEPS = 200  # gauss_newton's steps (accepted or not) at most
BOUND_SHARE = 1e-9  # an unknown within this share of its range from a bound is on it (gauss_newton's `interior`)
MU_GIVE_UP = 1e12  # damping beyond which a rejected step means no step helps (its length is ~1e-12 of Newton's)


def gauss_newton(run: Search, x0: NDArray, interior: bool = False) -> NDArray | None:
    """Levenberg–Marquardt from x0 on the problem's exact linearisation, inside the box; the final point, or None
    when the problem has no linearisation at x0 (the caller falls back to `polish`), or with `interior` as soon as
    an accepted point has an unknown on its bound (a caller that discards such a fit: a mis-set known parameter's
    fit beside a faulty channel walks to its bound in up to MAX_STEPS steps, each a simulation with sensitivities).

    Each step solves (H + mu diag H) s = -g with H = J'J, g = J'r in box-width units and evaluates the residuals and
    Jacobian at the (clipped) new point together (a long record's H and g summed over its samples by the problem's
    `normal`, no (R, D) Jacobian made): accepted when the sum of squares falls (mu shrinks), else mu grows
    and the step is retried. It stops when the proposed step's squared length in the metric H, over the residual
    variance, is below STEP_SD²: the step is then STEP_SD standard deviations of the estimate (H / s² is its Fisher
    information), far below what the data can tell.

    Near the minimum the last linearisation is not needed: when an undamped step of q standard deviations follows
    an undamped accepted one of q_prev, Gauss–Newton's contraction (q / q_prev, at most linear: it is superlinear
    on a small-residual fit) puts the step after it at q² / q_prev. Below LAST_SD (a twentieth of a standard
    deviation: 0.25 % of the estimate's variance) the step is taken on the residuals alone (a simulation without
    sensitivities, a third of the cost) and kept if the sum of squares falls, the search stopping there; else
    Levenberg–Marquardt goes on from the linearisation it has."""
    lo, hi = run.problem.lower, run.problem.upper
    width = hi - lo
    x = np.clip(np.asarray(x0, dtype=float), lo, hi)
    got = _normal_point(run, x, width)
    if got is None:
        return None
    r, H, g = got
    ssq = float(r @ r)
    mu = 0.0
    q_prev = 0.0  # the last accepted undamped step [standard deviations] (0: none)
    for _ in range(MAX_STEPS):
        d = np.diag(H)
        try:
            s = np.linalg.solve(H + mu * np.diag(d), -g)
        except np.linalg.LinAlgError:
            s = -g / np.where(d > 0, d, 1.0)
        x_new = np.clip(x + s * width, lo, hi)
        step = (x_new - x) / width
        variance = max(ssq / max(r.size - x.size, 1), 1e-300)
        q = float(np.sqrt(max(float(step @ H @ step), 0.0) / variance))
        if q < STEP_SD:
            break
        # the next step would be below LAST_SD: take this one on the residuals alone, and stop
        if mu == 0.0 and q * q < LAST_SD * q_prev and run.problem.residuals is not None:
            r_new = run.evaluate_residuals(x_new[None, :], keep=True)[0]
            if float(r_new @ r_new) < ssq:
                return x_new
            q_prev, mu = 0.0, 1e-3
            continue
        got = _normal_point(run, x_new, width)
        ssq_new = float(got[0] @ got[0]) if got is not None else np.inf
        if ssq_new < ssq:
            x, (r, H, g), ssq = x_new, got, ssq_new
            if interior and np.any(np.minimum(x - lo, hi - x) <= BOUND_SHARE * width):
                return None
            q_prev = q if mu == 0.0 else 0.0
            mu = mu / 4 if mu > 1e-6 else 0.0
        else:
            q_prev, mu = 0.0, max(4 * mu, 1e-3)
            if mu > MU_GIVE_UP:  # no step of any length lowers the cost: x is the minimum to round-off
                break
    return x


GEMM_COPY_BYTES = 4 * 2**20  # a Jacobian up to this size gets its J'J by gemm against a copy (see _normal_equations)


def _normal_equations(J: NDArray, r: NDArray, width: NDArray) -> tuple[NDArray, NDArray]:
    """H = J'J and g = J'r (J (R, D) per unit of each unknown) in box-width units, (D, D) and (D,): the products on
    the problem's J, scaled after; once per accepted point, not per damping tried. J'J against a copy of J: NumPy
    sends J.T @ J to BLAS's syrk, three times slower than gemm on a tall J of a few columns (copy included); a long
    record's J (beyond GEMM_COPY_BYTES) is not copied."""
    other = J.copy() if J.nbytes <= GEMM_COPY_BYTES else J
    return (J.T @ other) * np.outer(width, width), (J.T @ r) * width


def _normal_point(run: Search, x: NDArray, width: NDArray) -> tuple[NDArray, NDArray, NDArray] | None:
    """The residuals r (R,), H = J'J and g = J'r in box-width units at x, from one evaluation: the problem's normal
    equations when it has them (a long record: summed over the samples, no (R, D) Jacobian), else its Jacobian."""
    if run.problem.normal is not None:
        got = run.evaluate_normal(x)
        if got is None:
            return None
        _, r, H, g = got
        return r, H * np.outer(width, width), g * width
    got = run.evaluate_linearised(x)
    if got is None:
        return None
    _, r, J = got
    return (r, *_normal_equations(J, r, width))


@register
class LeastSquares(Optimizer):
    """Local trust-region least squares from x0 (or a random point in the box), until converged or out of budget."""

    name = "lsq"

    def _initialize(self, run: Search, x0: NDArray | None) -> Any:
        return {"x": run.start(x0)}

    def _step(self, run: Search, state: Any) -> bool | None:
        try:
            exact = run.problem.linearised is not None or run.problem.normal is not None
            x = gauss_newton(run, state["x"]) if exact else None
            state["x"] = polish(run, state["x"]) if x is None else x
        except BudgetExhausted:
            pass
        return False
