"""What the augmentation loop needs of the system under diagnosis (the car, a lumped rig or a damper on a bench):
its problems over any set of unknowns, its validation J, its likelihood-ratio statistic and its residual scale.
Each system builds one (`systems.<name>.diagnosis`); the loop (`loop.py`) and the tests of a claim (`claims.py`)
only read it."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..optimizers.base import Problem
from .attribution import SCREEN_TOL, Candidate, Fit, fit_free, fit_intervals, linear_fit


@dataclass(frozen=True)
class Subject:
    """What the loop needs of the system under diagnosis (the car or a damper on a bench).

    problem_for(names): the training problem over the unknowns `names` (declared first, then candidates'
    parameters) and a start value for each; validation_J(names, x): J on the validation data, and per file;
    statistic(current): the LR function (J_before, J_with) -> statistic for tests against the fit `current`;
    scale(fit): the variance of one training residual entry at a fit (for intervals).
    """

    specs: dict[str, Candidate]
    declared: frozenset[str]
    problem_for: Callable[[tuple[str, ...]], tuple[Problem, NDArray]]
    validation_J: Callable[[tuple[str, ...], NDArray], tuple[float, dict[str, float] | None]]
    residual_count: int
    statistic: Callable[[Fit], Callable[[float, float], float]]
    scale: Callable[[Fit], float]
    min_gain: float = 0.0
    noise_limit: float | None = None  # training J at or below which the residual is noise (None: J is not chi²)
    screen: Subject | None = None  # a long record's screening window (window.py): the candidates are ranked on it
    # the training problem over `names` on the exact integrator with its exact sensitivities, None where the model
    # is not the linear car (known parameters' fits by Levenberg–Marquardt on it: attribution.linear_fit)
    linear_for: Callable[[tuple[str, ...]], Problem | None] | None = None

    def J_at(self, fit: Fit) -> Fit:
        """`fit`'s point with its training J on this subject's data (the screening window's J of a whole-record
        fit)."""
        J = float(self.problem_for(fit.names)[0].cost(np.asarray(fit.x, dtype=float)[None, :])[0])
        return Fit(fit.names, fit.x, J if np.isfinite(J) else float("inf"), 1, fit.fixed)

    def intervals(self, fit: Fit) -> NDArray:
        """95 % half-widths at a fit over its free unknowns (NaN for the fixed ones): from the exact sensitivities of
        the linear car where that is the model (`linear_for`)."""
        linear = self.linear_for(fit.names) if self.linear_for is not None and not fit.fixed else None
        return fit_intervals(self.problem_for(fit.names)[0], fit, self.scale(fit), linear)

    def fit(self, names: tuple[str, ...], x0: NDArray, free: NDArray, budget: int) -> Fit:
        """The fit over `names` from x0 (the unknowns not `free` held): Levenberg–Marquardt on the exact linear car
        where every unknown is free and it applies (`linear_for`), else the trust region, to SCREEN_TOL (the LR to
        about 1e-7 R: a test's fit, not the final polish)."""
        problem = self.problem_for(names)[0]
        free = np.asarray(free, dtype=bool)
        linear = self.linear_for(names) if self.linear_for is not None and free.all() else None
        got = None if linear is None else linear_fit(problem, linear, x0, budget)
        return got if got is not None else fit_free(problem, x0, free, budget, tol=SCREEN_TOL)
