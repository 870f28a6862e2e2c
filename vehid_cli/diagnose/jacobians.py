"""The forward-difference Jacobian of a problem's residuals at a point, and the problem over some of its unknowns:
what the candidate fits, their intervals and the score screening share (a long record's J'J summed without J); and
J'J from a problem's exact sensitivities where it has them (the linear car's)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..optimizers.base import Problem


def restricted(problem: Problem, x: NDArray, free: NDArray) -> Problem:
    """The problem over the unknowns where `free` is True, the others held at their value in x."""
    x = np.asarray(x, dtype=float)
    free = np.asarray(free, dtype=bool)

    def full(X: NDArray) -> NDArray:
        out = np.repeat(x[None, :], len(X), axis=0)
        out[:, free] = X
        return out

    cr = None if problem.residuals is None else (lambda X: problem.residuals(full(X)))
    gram = None if problem.gram is None else (lambda X, scale, entries=None: problem.gram(full(X), scale, entries))
    names = tuple(n for n, f in zip(problem.names, free, strict=True) if f)
    return Problem(problem.lower[free], problem.upper[free], lambda X: problem.cost(full(X)), cr, problem.penalty,
                   names, gram=gram)  # fmt: skip


def forward_jacobian(problem: Problem, x: NDArray) -> tuple[NDArray, NDArray]:
    """The Jacobian (R, D) of the problem's residuals at x (forward differences, one batch) and the residual (R,)."""
    X, step = _forward_points(problem, x)
    _, R = problem.residuals(X)
    with np.errstate(over="ignore", invalid="ignore"):  # a step into an unstable model: inf columns, not a warning
        R[1:] -= R[0][None, :]  # in place: a long record's (D + 1, R) residuals are tens of MB per copy
        R[1:] /= step[:, None]
    return R[1:].T, R[0]


def _forward_points(problem: Problem, x: NDArray) -> tuple[NDArray, NDArray]:
    """The points (D + 1, D) of a forward-difference Jacobian at x (x, then a step along each unknown, inward at the
    upper bound) and the steps (D,)."""
    width = problem.upper - problem.lower
    h = 1e-6 * np.maximum(np.abs(x), 1e-3 * width)
    step = np.where(x + h <= problem.upper, h, -h)
    return np.vstack([x[None, :], x[None, :] + np.diag(step)]), step


def forward_normal(problem: Problem, x: NDArray) -> NDArray:
    """J'J (D, D) of `forward_jacobian`'s J at x: summed over a long record without J (`Problem.gram`) where the
    problem has that, else from J."""
    if problem.gram is not None:
        X, step = _forward_points(problem, x)
        with np.errstate(all="ignore"):
            G = problem.gram(X, step, None)
        if G is not None:
            return G[:-1, :-1]
    Jac, _ = forward_jacobian(problem, x)
    with np.errstate(all="ignore"):  # a Jacobian of penalised or diverging cars: J'J not finite, which callers test
        return Jac.T @ Jac


def exact_normal(linear: Problem, x: NDArray) -> NDArray | None:
    """J'J (D, D) at x from the problem's exact sensitivities (one simulation of the response and its derivatives,
    where forward differences take D + 1; a long record's summed without J); None where it has none there."""
    with np.errstate(all="ignore"):
        if linear.normal is not None:
            got = linear.normal(np.asarray(x, dtype=float))
            return None if got is None else np.asarray(got[2])
        got = linear.linearised(np.asarray(x, dtype=float)) if linear.linearised is not None else None
        return None if got is None else got[2].T @ got[2]
