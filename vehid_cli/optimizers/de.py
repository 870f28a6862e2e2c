"""Differential evolution DE/rand/1/bin (Storn & Price 1997), a population method beyond the paper's three.

For every target x_i of the population (N >= 4):

* mutant ``m = x_r0 + F (x_r1 - x_r2)`` with r0, r1, r2 distinct, different from i, drawn uniformly;
* binomial crossover: ``u_j = m_j`` where ``U(0,1) < CR`` or ``j = j_rand`` (one forced component), else
  ``x_ij``;
* selection: u replaces x_i when ``f(u) <= f(x_i)`` (ties accepted, letting the population drift on plateaus).

All N trial vectors of a generation are built from the same parent population and evaluated in one batch
(the classic synchronous DE generation).

Choices (documented):

* ``F = 0.5``, ``CR = 0.9`` (Storn & Price's recommended start values). No dither by default; with option
  ``dither=True`` F is drawn uniform in [0.5, 1) once per generation (Das et al. 2005, "dither"), which helps
  on badly scaled problems at the cost of slower final convergence.
* Bounds: bounce-back (Price, Storn & Lampinen 2005, section 4.3.1): a component below the lower bound is
  reset to ``lb + U(0,1) (x_r0,j - lb)`` and one above the upper bound to ``ub - U(0,1) (ub - x_r0,j)``,
  i.e. between the base vector and the violated bound. Unlike clipping, this keeps points off the wall
  while still allowing them close to it.
* Initial population uniform in the box, individual 0 replaced by ``x0`` when given.

Options: ``F`` (0.5), ``CR`` (0.9), ``dither`` (False).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .base import Optimizer, Search, register


@dataclass
class _DEState:
    pop: NDArray  # (N, D)
    score: NDArray  # (N,)


def distinct_indices(n: int, k: int, rng: np.random.Generator) -> NDArray:
    """(n, k) indices: row i holds k distinct integers from range(n), none equal to i (uniform)."""
    keys = rng.random((n, n))
    keys[np.arange(n), np.arange(n)] = np.inf  # never pick the target itself
    return np.argsort(keys, axis=1)[:, :k]


@register
class DE(Optimizer):
    """DE/rand/1/bin with F = 0.5 (optionally dithered), CR = 0.9 and bounce-back bounds."""

    name = "de"
    min_population = 4  # DE/rand/1 draws three partners distinct from the target

    def __init__(self, population: int = 20, iterations: int = 50, **options: Any):
        super().__init__(population, iterations, **options)
        self.F = float(options.get("F", 0.5))
        self.CR = float(options.get("CR", 0.9))
        self.dither = bool(options.get("dither", False))

    def _initialize(self, run: Search, x0: NDArray | None) -> _DEState:
        pop = run.uniform(self.population)
        if x0 is not None:
            pop[0] = x0
        return _DEState(pop=pop, score=run.evaluate(pop))

    def _step(self, run: Search, state: _DEState) -> None:
        lo, hi = run.problem.lower, run.problem.upper
        rng = run.rng
        n, d = state.pop.shape
        f_scale = rng.uniform(0.5, 1.0) if self.dither else self.F
        r = distinct_indices(n, 3, rng)
        base = state.pop[r[:, 0]]
        mutant = base + f_scale * (state.pop[r[:, 1]] - state.pop[r[:, 2]])
        cross = rng.random((n, d)) < self.CR
        cross[np.arange(n), rng.integers(0, d, size=n)] = True
        trial = np.where(cross, mutant, state.pop)
        # bounce-back between the base vector and the violated bound
        u = rng.random((n, d))
        trial = np.where(trial < lo, lo + u * (base - lo), trial)
        trial = np.where(trial > hi, hi - u * (hi - base), trial)
        score = run.evaluate(trial)
        accept = score <= state.score
        state.pop[accept] = trial[accept]
        state.score[accept] = score[accept]
