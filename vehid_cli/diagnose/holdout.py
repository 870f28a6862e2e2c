"""Held-out blocks: without a --validate run, every HOLDOUT_EVERY-th block of BLOCK samples of the training data
is kept out of every fit and gives the validation J; the problem on the kept residual entries only."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..identify.objectives import mean_square
from ..optimizers.base import Problem

BLOCK = 100  # samples per hold-out block
HOLDOUT_EVERY = 4  # without --validate, every 4th block is held out


def block_size(n: int) -> int:
    """Samples per hold-out block: BLOCK, smaller on short data so that every run has held-out blocks."""
    return max(1, min(BLOCK, n // (2 * HOLDOUT_EVERY)))


def holdout_blocks(n: int) -> NDArray:
    """(n,) True on the held-out samples: every HOLDOUT_EVERY-th block of block_size(n)."""
    return (np.arange(n) // block_size(n)) % HOLDOUT_EVERY == HOLDOUT_EVERY - 1


def masked(problem: Problem, keep: NDArray | None) -> Problem:
    """The problem on the kept residuals only (cost: their chi² per sample); diverging candidates (NaN, inf)
    are the optimizer's to penalise, without floating-point warnings. The problem's exact linearisation (the linear
    car's sensitivities), when it has one, is masked the same way (its rows of the kept entries), and so are its normal
    equations (a long record's: summed over the kept entries only)."""

    rows = None if keep is None else np.flatnonzero(keep)

    def cr(X):
        with np.errstate(all="ignore"):
            if rows is not None and problem.kept is not None and len(X) > 1 and len(X) * keep.size * 8 > IN_PLACE_BYTES:
                r = problem.kept(X, rows)  # a long record's batch: its kept entries only, no (P, R) array
                return mean_square(r), r
            _, r = problem.residuals(X)
            if r.nbytes <= IN_PLACE_BYTES:
                r = r if keep is None else r[:, keep]
                return np.mean(r**2, axis=1), r
            r = r if rows is None else kept_in_place(r, rows)  # a long record's: no second (P, R) array
            return mean_square(r), r

    def linearised(x: NDArray) -> tuple[float, NDArray, NDArray] | None:
        got = problem.linearised(x)
        if got is None:
            return None
        _, r, jac = got
        if keep is not None:
            r, jac = r[keep], jac[keep]
        with np.errstate(all="ignore"):
            return float(mean_square(r)), r, jac

    def normal(x: NDArray) -> tuple[float, NDArray, NDArray, NDArray] | None:
        got = problem.normal(x) if rows is None else problem.normal(x, rows)
        if got is None:
            return None
        _, r, H, g = got
        r = r if keep is None else r[keep]
        with np.errstate(all="ignore"):
            return float(mean_square(r)), r, H, g

    def gram(X: NDArray, scale: NDArray, entries: NDArray | None = None) -> NDArray | None:
        at = rows if entries is None else (entries if rows is None else rows[entries])
        return problem.gram(X, scale, at)

    lin = None if problem.linearised is None else linearised
    return Problem(problem.lower, problem.upper, lambda X: cr(X)[0], cr, problem.penalty, problem.names, lin,
                   normal=None if problem.normal is None else normal,
                   gram=None if problem.gram is None else gram)  # fmt: skip


def kept_in_place(r: NDArray, rows: NDArray) -> NDArray:
    """The kept entries `rows` (increasing) of each residual vector of r (P, R), moved to the front of its own row:
    a view (P, rows.size) of r's memory, not a second array beside it (a long record's Jacobian batch of residuals is
    50 MB, its kept entries 37). r is the caller's to give up."""
    n = rows.size
    for i in range(r.shape[0]):
        r[i, :n] = r[i, rows]
    return r[:, :n]


IN_PLACE_BYTES = 16 * 2**20  # residuals above this (a long record's) are masked in place and squared a part at a time
# (`mean_square`, no (P, R) array of squares): the same numbers to round-off (r[:, keep] is in Fortran order, whose
# rows NumPy sums in another order), not bit for bit
