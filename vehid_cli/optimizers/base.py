"""The optimizer framework: a fixed outer loop (budget, counting, best-so-far, penalties) around one hook.

An algorithm implements ``_initialize`` (make its first population and evaluate it) and ``_step``
(advance one iteration); ``minimize`` is the same for all of them. All evaluations go through
``Search.evaluate``, which takes a whole population at once (shape (P, D)), counts every evaluation,
replaces non-finite costs by a finite penalty, and records the best-cost history.
"""

from __future__ import annotations

import dataclasses
import time
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

BatchCost = Callable[[NDArray], NDArray]  # (P, D) -> (P,)
CostAndResiduals = Callable[[NDArray], tuple[NDArray, NDArray]]  # (P, D) -> costs (P,), residuals (P, R)
# x (D,) -> cost, residuals (R,) and their exact derivatives d r / dx (R, D) from one simulation; None where unavailable
Linearised = Callable[[NDArray], "tuple[float, NDArray, NDArray] | None"]
# x (D,) -> cost, residuals (R,), J'J (D, D) and J'r (D,) of that Jacobian, summed over a long record without it;
# an optional second argument, entries (k,) or None: the sums over those residual entries only (None where unavailable)
NormalEquations = Callable[..., "tuple[float, NDArray, NDArray, NDArray] | None"]
KeptResiduals = Callable[[NDArray, NDArray], NDArray]  # (P, D), entries (k,) -> residuals (P, k) at those entries
# points X (m + 1, D) (a centre, then m others), divisors (m,), entries (k,) or None -> the Gram matrix (m + 1, m + 1)
# of [J r] at those entries (r the centre's residuals, J's column j (r_{j+1} - r_0) / divisor_j), summed over a long
# record without the (m, R) differences (identify/forward.py); None where it does not apply
ForwardGram = Callable[[NDArray, NDArray, "NDArray | None"], "NDArray | None"]


@dataclass(frozen=True)
class Problem:
    """Minimise cost(x) over the box lower <= x <= upper.

    ``cost`` evaluates a population (P, D) -> (P,). ``residuals`` (optional) evaluates a population to
    (costs (P,), residual vectors (P, R)) from one simulation; least-squares methods minimise the sum of
    squared residuals (the Gaussian likelihood) and report the cost.
    ``penalty`` is the finite cost given to points whose cost is NaN or infinite (unstable models).
    """

    lower: NDArray
    upper: NDArray
    cost: BatchCost
    residuals: CostAndResiduals | None = None
    penalty: float = 1e10
    names: tuple[str, ...] = ()
    linearised: Linearised | None = None  # cost, residuals and their exact Jacobian at one point (None: not known)
    normal: NormalEquations | None = None  # the same as normal equations (a long record: no (R, D) Jacobian made)
    kept: KeptResiduals | None = None  # `residuals` at some entries only, the same numbers (diagnose/holdout.py)
    gram: ForwardGram | None = None  # a forward-difference Jacobian's J'J, J'r, r'r without it (a long record)

    @property
    def dim(self) -> int:
        return int(np.asarray(self.lower).size)


@dataclass(frozen=True)
class OptimizeResult:
    """Best point found, its cost, and how the search went (evaluations counted, history of best cost)."""

    x: NDArray
    cost: float
    evaluations: int
    iterations: int
    penalised: int
    wall_s: float
    history_evals: NDArray  # cumulative evaluations after each batch
    history_cost: NDArray  # best cost after each batch
    message: str = ""
    residuals: NDArray | None = None  # the weighted residuals (R,) at x when the search kept them (else None)


class BudgetExhausted(Exception):
    """Raised inside an algorithm's step when the evaluation budget is spent; ends the run cleanly."""


@dataclass
class Search:
    """The state every algorithm shares: problem, random stream, budget, counters, best so far."""

    problem: Problem
    rng: np.random.Generator
    budget: int
    evaluations: int = 0
    penalised: int = 0
    best_x: NDArray | None = None
    best_cost: float = np.inf
    history_evals: list[int] = field(default_factory=list)
    history_cost: list[float] = field(default_factory=list)
    best_residuals: NDArray | None = None  # the residuals at best_x when an evaluation kept them (`keep`), else None

    @property
    def remaining(self) -> int:
        return self.budget - self.evaluations

    def evaluate(self, X: NDArray) -> NDArray:
        """Costs of a population (P, D), clipped into the box first. Truncated to the remaining budget:
        points past the budget get +inf and BudgetExhausted is raised after recording the ones that fit."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        lo, hi = self.problem.lower, self.problem.upper
        X = np.clip(X, lo, hi)
        take = min(len(X), max(self.remaining, 0))
        costs = np.full(len(X), np.inf)
        if take > 0:
            raw = np.asarray(self.problem.cost(X[:take]), dtype=float).reshape(take)
            bad = ~np.isfinite(raw)
            self.penalised += int(bad.sum())
            raw = np.where(bad, self.problem.penalty, raw)
            costs[:take] = raw
            self.evaluations += take
            i = int(np.argmin(raw))
            if raw[i] < self.best_cost:
                self.best_cost, self.best_x, self.best_residuals = float(raw[i]), X[i].copy(), None
            self.history_evals.append(self.evaluations)
            self.history_cost.append(self.best_cost)
        if take < len(X):
            raise BudgetExhausted
        return costs

    def evaluate_linearised(self, x: NDArray) -> tuple[NDArray, NDArray, NDArray] | None:
        """Cost, residuals (R,) and their exact Jacobian (R, D) at x (clipped into the box) from the problem's
        `linearised` (one simulation of the response and its sensitivities), counted as one evaluation and tracked
        like ``evaluate`` (a new best keeps its residuals: the caller must not modify them); None when the problem
        has none or its numbers there are not finite. Raises BudgetExhausted when no evaluation is left."""
        return self._evaluate_one(self.problem.linearised, x)

    def evaluate_normal(self, x: NDArray) -> tuple[NDArray, NDArray, NDArray, NDArray] | None:
        """Cost, residuals (R,), J'J (D, D) and J'r (D,) at x (clipped into the box) from the problem's `normal`
        equations (a long record's ``evaluate_linearised`` without its Jacobian), counted and tracked alike."""
        return self._evaluate_one(self.problem.normal, x)

    def _evaluate_one(self, at: Callable | None, x: NDArray) -> tuple | None:
        """`at(x)` (the problem's `linearised` or `normal`: the cost, then arrays) at x clipped into the box, counted
        as one evaluation and tracked; None when the problem has no such function or its numbers are not finite."""
        if at is None:
            return None
        if self.remaining < 1:
            raise BudgetExhausted
        x = np.clip(np.asarray(x, dtype=float), self.problem.lower, self.problem.upper)
        got = at(x)
        if got is None:
            return None
        return (np.asarray(got[0]), *got[1:]) if self._track_one(x, got) else None

    def _track_one(self, x: NDArray, got: tuple) -> bool:
        """One evaluation at x giving `got` (the cost, then arrays) counted and tracked; whether all of it is finite."""
        self.evaluations += 1
        ok = bool(np.isfinite(got[0])) and all(np.all(np.isfinite(a)) for a in got[1:])
        if not ok:
            self.penalised += 1
        elif got[0] < self.best_cost:  # got[1] is the residual vector of both kinds
            self.best_cost, self.best_x, self.best_residuals = float(got[0]), x.copy(), got[1]
        self.history_evals.append(self.evaluations)
        self.history_cost.append(self.best_cost)
        return ok

    def evaluate_gram(self, X: NDArray, scale: NDArray) -> NDArray | None:
        """The problem's `gram` of the points X (m + 1, D) (clipped into the box): the centre X[0] (already evaluated
        by the caller) and m others, counted as m evaluations; None (nothing counted) when the problem has none, it
        does not apply or its sums are not finite (the caller then evaluates the others' residuals). Their costs
        are not tracked: a forward difference's points are not candidates for the best. Raises BudgetExhausted
        (evaluating nothing) when the m do not fit the budget."""
        if self.problem.gram is None:
            return None
        X = np.clip(np.atleast_2d(np.asarray(X, dtype=float)), self.problem.lower, self.problem.upper)
        if len(X) - 1 > self.remaining:
            raise BudgetExhausted
        G = self.problem.gram(X, np.asarray(scale, dtype=float), None)
        if G is None or not np.all(np.isfinite(G)):
            return None
        self.evaluations += len(X) - 1
        self.history_evals.append(self.evaluations)
        self.history_cost.append(self.best_cost)
        return G

    def evaluate_residuals(self, X: NDArray, keep: bool = False) -> NDArray:
        """Residual vectors (P, R) of a population, counted and tracked like ``evaluate``; with `keep` a new best
        keeps its residuals (`best_residuals`, the result's: the caller promises not to modify them).

        Raises BudgetExhausted (evaluating nothing) when the whole batch does not fit the budget, and
        ValueError when the problem has no residuals.
        """
        if self.problem.residuals is None:
            raise ValueError("this problem has no residual vector")
        X = np.clip(np.atleast_2d(np.asarray(X, dtype=float)), self.problem.lower, self.problem.upper)
        if len(X) > self.remaining:
            raise BudgetExhausted
        costs, residuals = self.problem.residuals(X)
        costs = np.asarray(costs, dtype=float).reshape(len(X))
        residuals = np.asarray(residuals, dtype=float)
        bad = ~np.isfinite(costs) | ~np.all(np.isfinite(residuals), axis=1)
        self.penalised += int(bad.sum())
        costs = np.where(bad, self.problem.penalty, costs)
        if bad.any():  # in place, and only then: a long record's residuals are tens of MB per copy
            residuals = np.array(residuals)
            residuals[bad] = np.sqrt(self.problem.penalty)
        self.evaluations += len(X)
        i = int(np.argmin(costs))
        if costs[i] < self.best_cost:
            self.best_cost, self.best_x = float(costs[i]), X[i].copy()
            self.best_residuals = residuals[i] if keep and not bad[i] else None
        self.history_evals.append(self.evaluations)
        self.history_cost.append(self.best_cost)
        return residuals

    def start(self, x0: NDArray | None) -> NDArray:
        """Where a local method starts: x0 when given, else a uniform draw in the box from the run's stream
        (never the box centre: with symmetric bounds that is the configured value, often the truth)."""
        return self.uniform(1)[0] if x0 is None else np.clip(x0, self.problem.lower, self.problem.upper)

    def uniform(self, n: int) -> NDArray:
        """n points drawn uniformly in the box."""
        lo, hi = self.problem.lower, self.problem.upper
        return lo + (hi - lo) * self.rng.random((n, lo.size))


class Optimizer(ABC):
    """Base of all algorithms. Subclasses set ``name`` and implement ``_initialize`` and ``_step``."""

    name: ClassVar[str]
    min_population: ClassVar[int] = 2

    def __init__(self, population: int = 20, iterations: int = 50, **options: Any):
        if population < self.min_population:
            raise ValueError(f"{self.name} needs a population of at least {self.min_population}")
        if iterations < 1:
            raise ValueError("iterations must be at least 1")
        self.population = int(population)
        self.iterations = int(iterations)
        self.options = options

    def default_budget(self) -> int:
        """Evaluations allowed when none is given: population x iterations (the paper's 20 x 50 = 1000)."""
        return self.population * self.iterations

    def minimize(
        self,
        problem: Problem,
        rng: np.random.Generator,
        budget: int | None = None,
        x0: NDArray | None = None,
    ) -> OptimizeResult:
        """Run the algorithm until the evaluation budget is spent (exactly: a given budget is never cut short by the
        iteration count) or it converges; without a budget, population x iterations evaluations."""
        lo, hi = np.asarray(problem.lower, dtype=float), np.asarray(problem.upper, dtype=float)
        if lo.shape != hi.shape or lo.ndim != 1 or np.any(~(lo < hi)):
            raise ValueError("bounds must be 1-D with lower < upper")
        problem = dataclasses.replace(problem, lower=lo, upper=hi)
        run = Search(problem=problem, rng=rng, budget=int(budget if budget is not None else self.default_budget()))
        start = time.perf_counter()
        iterations, message = 0, "iterations done"
        try:
            state = self._initialize(run, None if x0 is None else np.clip(np.asarray(x0, dtype=float), lo, hi))
            while (budget is not None or iterations < self.iterations) and run.remaining > 0:
                iterations += 1
                before = run.evaluations
                if self._step(run, state) is False or run.evaluations == before:  # converged, or nothing left to try
                    message = "converged"
                    break
            if run.remaining <= 0:
                message = "budget spent"
        except BudgetExhausted:
            message = "budget spent"
        return OptimizeResult(
            x=run.best_x if run.best_x is not None else (lo + hi) / 2,
            cost=run.best_cost,
            evaluations=run.evaluations,
            iterations=iterations,
            penalised=run.penalised,
            wall_s=time.perf_counter() - start,
            history_evals=np.asarray(run.history_evals, dtype=np.int64),
            history_cost=np.asarray(run.history_cost, dtype=float),
            message=message,
            residuals=run.best_residuals if run.best_x is not None else None,
        )

    @abstractmethod
    def _initialize(self, run: Search, x0: NDArray | None) -> Any:
        """Create and evaluate the first population (seeded with x0 when given); return the state."""

    @abstractmethod
    def _step(self, run: Search, state: Any) -> bool | None:
        """One iteration on the population; return False to stop early (converged)."""


REGISTRY: dict[str, type[Optimizer]] = {}


def register(cls: type[Optimizer]) -> type[Optimizer]:
    """Class decorator: make an algorithm available by its ``name`` (SPEC section 3)."""
    REGISTRY[cls.name] = cls
    return cls


def forward_jacobian(problem: Problem, x: NDArray) -> tuple[NDArray, NDArray]:
    """The Jacobian (R, D) of the problem's residuals at x (forward differences, one batch) and the residual (R,)."""
    X, step = forward_points(problem, x)
    _, R = problem.residuals(X)
    with np.errstate(over="ignore", invalid="ignore"):  # a step into an unstable model: inf columns, not a warning
        R[1:] -= R[0][None, :]  # in place: a long record's (D + 1, R) residuals are tens of MB per copy
        R[1:] /= step[:, None]
    return R[1:].T, R[0]


def forward_points(problem: Problem, x: NDArray) -> tuple[NDArray, NDArray]:
    """The points (D + 1, D) of a forward-difference Jacobian at x (x, then a step along each unknown, inward at the
    upper bound) and the steps (D,)."""
    width = problem.upper - problem.lower
    h = 1e-6 * np.maximum(np.abs(x), 1e-3 * width)
    step = np.where(x + h <= problem.upper, h, -h)
    return np.vstack([x[None, :], x[None, :] + np.diag(step)]), step


def exact_normal_equations(problem: Problem, x: NDArray) -> tuple[NDArray, NDArray] | None:
    """J'J (D, D) and J'r (D,) of the problem's weighted residuals r at x from its exact sensitivities (one simulation
    of the response and its derivatives, where forward differences take D + 1): its normal equations where it has them
    (a long record's, summed without J), else its linearisation; None where it has neither there."""
    x = np.asarray(x, dtype=float)
    with np.errstate(all="ignore"):
        if problem.normal is not None:
            got = problem.normal(x)
            return None if got is None else (np.asarray(got[2]), np.asarray(got[3]))
        got = problem.linearised(x) if problem.linearised is not None else None
        return None if got is None else (got[2].T @ got[2], got[2].T @ got[1])
