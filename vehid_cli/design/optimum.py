"""The best vector of the designed variables for fixed sensors: differential evolution (deferred updating, the
population scored in parallel by the `Scorer`, the shape an integer variable, its generator spawned from
`design.search.seed`), then coordinate sweeps over a grid through its optimum until none improves it.

SciPy's DE, not optimizers/de: ours lacks an integer variable (the shape) and a convergence stop; designs would change.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..config.design import Design
from .criterion import penalised
from .plan import Plan
from .scoring import Progress, Scorer
from .space import Space, line_through


def evolve(scorer: Scorer, space: Space, base: Plan, design: Design, progress: Progress) -> NDArray:
    """The best vector of the free variables by differential evolution (deferred updating, vectorised)."""
    from scipy.optimize import differential_evolution

    search = design.search
    n = len(space.free)
    (seq,) = np.random.SeedSequence(search.seed).spawn(1)
    generation = [0]

    def objective(XT: NDArray) -> NDArray:
        return np.array([penalised(s.criterion) for s in scorer(space, base, XT.T)])

    def callback(*_args, **_kwargs) -> None:
        generation[0] += 1
        progress("search", generation[0], search.iterations)

    result = differential_evolution(
        objective, list(zip(space.lower, space.upper, strict=True)), maxiter=search.iterations,
        popsize=max(1, math.ceil(search.population / n)), rng=np.random.default_rng(seq), polish=False,
        updating="deferred", vectorized=True, callback=callback, x0=np.clip(space.vector(base), space.lower,
                                                                          space.upper),
        integrality=[name == "shape" for name in space.free],
    )  # fmt: skip
    return np.asarray(result.x, dtype=float)


def polish(scorer: Scorer, space: Space, base: Plan, x: NDArray, best: float, points: int) -> tuple[NDArray, float]:
    """Coordinate sweeps over the grid through x until none improves the criterion (at most 3 passes)."""
    for _ in range(3):
        improved = False
        for name in space.free:
            grid, X = line_through(space, x, name, points)
            scores = [penalised(s.criterion) for s in scorer(space, base, X)]
            k = int(np.argmin(scores))
            if scores[k] < best - 1e-9 * abs(best):
                x, best, improved = X[k], scores[k], True
        if not improved:
            break
    return x, best
