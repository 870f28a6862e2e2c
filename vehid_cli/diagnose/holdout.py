"""Held-out blocks: without a --validate run, every HOLDOUT_EVERY-th block of BLOCK samples of the training data
is kept out of every fit and gives the validation J; the problem on the kept residual entries only."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

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
    car's sensitivities), when it has one, is masked the same way (its rows of the kept entries)."""

    def cr(X):
        with np.errstate(all="ignore"):
            _, r = problem.residuals(X)
            r = r if keep is None else r[:, keep]
            return np.mean(r**2, axis=1), r

    def linearised(x: NDArray) -> tuple[float, NDArray, NDArray] | None:
        got = problem.linearised(x)
        if got is None:
            return None
        _, r, jac = got
        if keep is not None:
            r, jac = r[keep], jac[keep]
        with np.errstate(all="ignore"):
            return float(np.mean(r**2)), r, jac

    lin = None if problem.linearised is None else linearised
    return Problem(problem.lower, problem.upper, lambda X: cr(X)[0], cr, problem.penalty, problem.names, lin)
