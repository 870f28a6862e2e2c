"""Trust-region least squares (scipy's 'trf') on the weighted residual vector, inside the box.

Minimising the sum of squared weighted residuals is the Gaussian maximum-likelihood estimate, which is
what reaches the Cramér–Rao bound. The Jacobian is a forward difference computed in ONE batched
evaluation of the D perturbed points (counted as D evaluations), reusing the residual at the centre.
A Jacobian above LONG_JACOBIAN_BYTES (a long record) is fitted compressed (`compressed.py`): the same steps on
D + 1 rows, without scipy's copies of the (R, D) matrix.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from .base import BudgetExhausted, Optimizer, Search, register
from .compressed import trf_compressed

JACOBIAN_STEP = 1e-7  # forward-difference step, as a fraction of each parameter's box width
LONG_JACOBIAN_BYTES = 16 * 2**20  # a Jacobian larger than this is fitted compressed (optimizers/compressed.py)


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

    def jacobian_rows(x: NDArray) -> NDArray:
        """(D, R): row j the residual's forward difference by unknown j."""
        r0 = residual(x)
        h = JACOBIAN_STEP * width
        step = np.where(x + h <= hi, h, -h)  # step inward at the upper bound
        X = x[None, :] + np.diag(step)
        R = run.evaluate_residuals(X)
        R -= r0[None, :]  # in place: a long record's Jacobian is tens of MB per copy
        R /= step[:, None]
        return R

    def jacobian(x: NDArray) -> NDArray:
        return jacobian_rows(x).T

    from scipy.optimize import least_squares  # 0.3 s to import: not when a config naming lsq is only validated
    from scipy.optimize._lsq.common import make_strictly_feasible  # what least_squares does to x0 (idempotent)

    x0 = np.clip(np.asarray(x0, dtype=float), lo + 1e-12 * width, hi - 1e-12 * width)
    x0 = make_strictly_feasible(x0, lo, hi)
    if residual(x0).size * x0.size * 8 > LONG_JACOBIAN_BYTES:  # a long record: the same steps on D + 1 rows
        return trf_compressed(residual, jacobian_rows, x0, lo, hi, width, tol, max_nfev)
    result = least_squares(
        residual, x0, jac=jacobian, bounds=(lo, hi), method="trf", x_scale=width,
        xtol=tol, ftol=tol, gtol=tol, max_nfev=max_nfev,
    )  # fmt: skip
    return result.x


@register
class LeastSquares(Optimizer):
    """Local trust-region least squares from x0 (or a random point in the box), until converged or out of budget."""

    name = "lsq"

    def _initialize(self, run: Search, x0: NDArray | None) -> Any:
        return {"x": run.start(x0)}

    def _step(self, run: Search, state: Any) -> bool | None:
        try:
            state["x"] = polish(run, state["x"])
        except BudgetExhausted:
            pass
        return False
