"""The problem over some of its unknowns, and J'J at a point: of the forward-difference Jacobian
(`optimizers.base.forward_jacobian`; a long record's summed without J) and from a problem's exact sensitivities where
it has them (the linear car's): what the candidate fits, their intervals and the score screening share."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..optimizers.base import Problem, exact_normal_equations, forward_jacobian, forward_points


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


def forward_normal(problem: Problem, x: NDArray) -> NDArray:
    """J'J (D, D) of `forward_jacobian`'s J at x: summed over a long record without J (`Problem.gram`) where the
    problem has that, else from J."""
    if problem.gram is not None:
        X, step = forward_points(problem, x)
        with np.errstate(all="ignore"):
            G = problem.gram(X, step, None)
        if G is not None:
            return G[:-1, :-1]
    Jac, _ = forward_jacobian(problem, x)
    with np.errstate(all="ignore"):  # a Jacobian of penalised or diverging cars: J'J not finite, which callers test
        return Jac.T @ Jac


def exact_normal(linear: Problem, x: NDArray) -> NDArray | None:
    """J'J (D, D) at x from the problem's exact sensitivities (`optimizers.base.exact_normal_equations`); None where
    it has none there."""
    got = exact_normal_equations(linear, x)
    return None if got is None else got[0]
