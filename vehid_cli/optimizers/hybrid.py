"""The project's best estimator: a global population phase, then a least-squares polish.

The global phase (differential evolution by default) spends a fraction of the budget finding the basin
of the global minimum; the trust-region polish (`lsq`) then converges to the maximum-likelihood estimate
in a few dozen evaluations. Both phases share one counted run, so the budget is the whole budget.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from . import abc, cpso, de, ga, nelder_mead  # noqa: F401  (the global phases it may run register themselves)
from .base import REGISTRY, BudgetExhausted, Optimizer, Search, register
from .lsq import polish


@register
class Hybrid(Optimizer):
    """Global phase (`global_algorithm`, `global_fraction` of the budget), then the `lsq` polish."""

    name = "hybrid"
    min_population = 4  # its default global phase is DE

    def __init__(self, population: int = 20, iterations: int = 50, **options: Any):
        super().__init__(population, iterations, **options)
        self.global_algorithm = str(options.get("global_algorithm", "de"))
        self.global_fraction = float(options.get("global_fraction", 0.5))

    def _initialize(self, run: Search, x0: NDArray | None) -> Any:
        inner = REGISTRY[self.global_algorithm](population=self.population, iterations=self.iterations)
        global_budget = int(self.global_fraction * run.budget)
        state = inner._initialize(run, x0)
        try:
            while run.evaluations + self.population <= global_budget:
                if inner._step(run, state) is False:
                    break
        except BudgetExhausted:
            pass
        return {"x": run.best_x}

    def _step(self, run: Search, state: Any) -> bool | None:
        try:
            state["x"] = polish(run, np.asarray(state["x"]))
        except BudgetExhausted:
            pass
        return False
