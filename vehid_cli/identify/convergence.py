"""Whether one fit's estimate is at its least-squares optimum (`optimum_offset`): the Gauss–Newton step from it, in
each unknown's standard deviations at the estimate. A global search (GA, PSO, ABC) ends where its budget does, not
at the optimum, and the bound's interval around where it stopped is as tight as the optimum's: it may not hold the
optimum at all (the paper's ABC, 1000 evaluations, on ../shared/data/vehicle/bump_run_linear.csv: Ix 490.8 ± 5.1
kg m², its optimum 9 kg m² away). At an optimum the step is round-off; OFFSET_SD standard deviations or more say the
interval is misplaced."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..optimizers.base import Problem, exact_normal_equations, forward_jacobian

OFFSET_SD = 1.0  # a Gauss–Newton step of this many standard deviations or more: not at the optimum (a 95 % interval
# that far off the optimum covers the true value 83 % of the time, not 95 %)
LEAST_SQUARES = ("lsq", "hybrid")  # searches that end with least squares on the weighted residuals
NORM_COSTS = ("f1", "f2")  # costs that are sums of norms (the paper's Eq. 8), not of squares


@dataclass(frozen=True)
class OptimumOffset:
    """One Gauss–Newton step from a fit's estimate: per unknown in its units and in its standard deviations (NaN
    where the unknown is held: on a bound, or without a finite sd)."""

    names: tuple[str, ...]
    step: NDArray  # (D,) [each unknown's unit]; 0 where held
    in_sd: NDArray  # (D,) step / sd

    @property
    def far(self) -> tuple[int, ...]:
        """The unknowns the step moves by OFFSET_SD standard deviations or more, the farthest first."""
        big = [j for j, s in enumerate(self.in_sd) if np.isfinite(s) and abs(s) >= OFFSET_SD]
        return tuple(sorted(big, key=lambda j: -abs(self.in_sd[j])))

    def describe(self, units: Mapping[str, str], algorithm: str, objective: str) -> str | None:
        """What a user must know when the estimate is not at the optimum (None when it is), and what to do: a search
        that ran out of iterations needs more, or lsq; lsq itself keeps the point of lowest cost it passed, which
        under the paper's f1 and f2 (sums of norms, not of squares) need not be the least-squares optimum."""
        if not self.far:
            return None
        moves = ", ".join(
            f"{self.names[j]} by {self.step[j]:+.4g} {units.get(self.names[j], '')}".rstrip()
            + f" ({abs(self.in_sd[j]):.2g} sd)"
            for j in self.far
        )
        if algorithm in LEAST_SQUARES and objective in NORM_COSTS:
            why = f"{algorithm} kept the point of lowest {objective} cost it passed"
            advice = "identify with identify.objective=wls: its cost is the least-squares one, so the fit ends there"
        else:
            why = f"{algorithm} stopped"
            advice = (
                "raise identify.algorithm.iterations (or identify.budget), or identify with lsq and "
                "identify.objective=wls, which end at the optimum"
            )
        return (
            f"the estimate is not at the least-squares optimum of its fit: one Gauss–Newton step from it moves "
            f"{moves}; the 95 % intervals (the bound at the estimate) are around where {why}, not around the "
            f"optimum: {advice}"
        )


def optimum_offset(problem: Problem, x: NDArray, sd: NDArray, held: NDArray) -> OptimumOffset | None:
    """The Gauss–Newton step from x on the problem's weighted residuals over the unknowns not `held` (on a bound: their
    optimum lies beyond the box), and that step over each unknown's standard deviation `sd`. The normal equations
    from the problem's exact sensitivities where it has them (a long record's summed over its samples, no Jacobian
    held), else from a forward-difference Jacobian (one batch of D + 1 evaluations). None where the problem gives no
    residuals, they are not finite, or no unknown is free."""
    x = np.asarray(x, dtype=float)
    sd = np.asarray(sd, dtype=float)
    free = ~np.asarray(held, dtype=bool) & np.isfinite(sd) & (sd > 0)
    if not free.any():
        return None
    normal = _normal_equations(problem, x)
    if normal is None:
        return None
    H, g = normal
    if not (np.all(np.isfinite(H)) and np.all(np.isfinite(g))):
        return None
    step = np.zeros(x.size)
    step[free] = np.linalg.lstsq(H[np.ix_(free, free)], -g[free], rcond=None)[0]
    with np.errstate(invalid="ignore", divide="ignore"):
        in_sd = np.where(free, step / np.where(free, sd, 1.0), np.nan)
    return OptimumOffset(names=tuple(problem.names), step=step, in_sd=in_sd)


def _normal_equations(problem: Problem, x: NDArray) -> tuple[NDArray, NDArray] | None:
    """J'J (D, D) and J'r (D,) of the problem's weighted residuals r at x (module docstring: which Jacobian)."""
    exact = exact_normal_equations(problem, x)
    if exact is not None or problem.residuals is None:
        return exact
    with np.errstate(all="ignore"):
        J, r = forward_jacobian(problem, x)
        return J.T @ J, J.T @ r
