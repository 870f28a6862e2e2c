"""Genetic algorithm with the MATLAB R2014a ``ga`` defaults the paper used (Gökdağ 2015, section 3).

The paper runs MATLAB's ``ga`` with population 20, 50 generations, ``TolFun = 0`` and otherwise default
options: crossover fraction 0.8, Gaussian mutation, elite count 0.05 x population. This module reproduces one
generation of MATLAB's ``stepGA``:

* ``nElite = ceil(0.05 N)`` (``EliteCount`` default since R2014a; 1 for N = 20) best individuals are copied.
* ``nXover = round(0.8 (N - nElite))`` crossover children (15 for N = 20), ``nMutate = N - nElite - nXover``
  mutation children (4), from ``nParents = 2 nXover + nMutate`` parents (34).
* Fitness scaling ``fitscalingrank``: the individual of rank r (1 = best) gets expectation proportional to
  ``1/sqrt(r)``, scaled so the expectations sum to ``nParents``.
* Selection ``selectionstochunif``: the expectations are laid out as consecutive sections of a line; one
  random offset in ``[0, 1/nParents)`` and ``nParents`` equally spaced pointers pick the parents, which are
  then shuffled (``randperm``) as in ``stepGA``.
* Crossover ``crossoverscattered``: one child per consecutive pair of parents; each gene comes from the
  first parent where a random binary mask is 1, else from the second.
* Mutation ``mutationgaussian`` (Scale = 1, Shrink = 1): child = parent + sigma_k * randn with
  ``sigma_k = Scale (1 - Shrink k / Generations) (ub - lb)`` per dimension at generation k = 1..Generations
  (MATLAB uses the ``PopInitRange`` width, which is the box when bounds are given); sigma falls linearly to 0
  at the last generation. ``Generations`` is the optimizer's ``iterations``; stepped past it (e.g. by
  ``hybrid``) sigma stays 0 instead of growing again.

Choices and deviations (documented):

* Children outside the bounds are clipped onto the violated bound. (MATLAB R2014a actually switches to
  ``mutationadaptfeasible`` when bounds are present; the paper states Gaussian mutation, so that is used.)
* The initial population is uniform in the box (``gacreationuniform``), individual 0 replaced by ``x0``.
* MATLAB's stall-generation and ``TolFun`` stopping rules are not applied (the paper sets ``TolFun = 0``);
  the run ends after ``iterations`` generations or when the budget is spent.
* Each generation evaluates the N - nElite new children in one batch; the elites keep their cost. With the
  defaults one run costs N + Generations (N - nElite) = 20 + 50 x 19 = 970 evaluations.

Options: ``elite_count``, ``crossover_fraction`` (0.8), ``scale`` (1.0), ``shrink`` (1.0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .base import Optimizer, Search, register


def rank_scaling(scores: ArrayLike, n_parents: int) -> NDArray:
    """MATLAB ``fitscalingrank``: expectation of rank r (1 = lowest cost) proportional to 1/sqrt(r), sum n_parents."""
    scores = np.asarray(scores, dtype=float)
    order = np.argsort(scores, kind="stable")
    expectation = np.empty(scores.size)
    expectation[order] = 1.0 / np.sqrt(np.arange(1, scores.size + 1))
    return n_parents * expectation / expectation.sum()


def stochastic_uniform(expectation: ArrayLike, n_parents: int, rng: np.random.Generator) -> NDArray:
    """MATLAB ``selectionstochunif``: one spin, n_parents equally spaced pointers over the expectation line."""
    wheel = np.cumsum(np.asarray(expectation, dtype=float)) / n_parents
    wheel[-1] = max(wheel[-1], 1.0)  # guard the last section against round-off
    positions = rng.random() / n_parents + np.arange(n_parents) / n_parents
    return np.searchsorted(wheel, positions, side="right")


@dataclass
class _GAState:
    pop: NDArray  # (N, D)
    score: NDArray  # (N,)
    generation: int = 0


@register
class GA(Optimizer):
    """MATLAB-default GA: elitism, rank scaling, stochastic-uniform selection, scattered crossover, Gaussian
    mutation with linearly shrinking sigma."""

    name = "ga"

    def __init__(self, population: int = 20, iterations: int = 50, **options: Any):
        super().__init__(population, iterations, **options)
        self.elite_count = int(options.get("elite_count", math.ceil(0.05 * self.population)))
        self.crossover_fraction = float(options.get("crossover_fraction", 0.8))
        self.scale = float(options.get("scale", 1.0))
        self.shrink = float(options.get("shrink", 1.0))
        if not 0 <= self.elite_count < self.population:
            raise ValueError("elite_count must be in [0, population)")

    def _initialize(self, run: Search, x0: NDArray | None) -> _GAState:
        pop = run.uniform(self.population)
        if x0 is not None:
            pop[0] = x0
        return _GAState(pop=pop, score=run.evaluate(pop))

    def _step(self, run: Search, state: _GAState) -> None:
        lo, hi = run.problem.lower, run.problem.upper
        rng = run.rng
        n, d = state.pop.shape
        state.generation += 1
        n_elite = self.elite_count
        n_xover = int(round(self.crossover_fraction * (n - n_elite)))
        n_mutate = n - n_elite - n_xover
        n_parents = 2 * n_xover + n_mutate

        expectation = rank_scaling(state.score, n_parents)
        parents = stochastic_uniform(expectation, n_parents, rng)
        parents = parents[rng.permutation(n_parents)]

        order = np.argsort(state.score, kind="stable")
        elite = order[:n_elite]

        # crossoverscattered: pairs (2i, 2i+1), gene from the first parent where the mask is set
        p1 = state.pop[parents[0 : 2 * n_xover : 2]]
        p2 = state.pop[parents[1 : 2 * n_xover : 2]]
        mask = rng.random((n_xover, d)) < 0.5
        xover = np.where(mask, p1, p2)

        # mutationgaussian: sigma shrinks linearly to 0 at the last generation
        scale = self.scale * max(0.0, 1.0 - self.shrink * state.generation / self.iterations)
        sigma = scale * (hi - lo)
        mutants = state.pop[parents[2 * n_xover :]] + sigma * rng.standard_normal((n_mutate, d))

        children = np.clip(np.vstack([xover, mutants]), lo, hi)
        child_score = run.evaluate(children)
        state.pop = np.vstack([state.pop[elite], children])
        state.score = np.concatenate([state.score[elite], child_score])
