"""Artificial Bee Colony (ABC), Gökdağ 2015 Eq. 12–14 after Karaboga & Basturk (2007) and Akay & Karaboga (2012).

SN = N/2 food sources (paper: "SN = N/2"). One iteration (Karaboga's reference code, ``ABC.m``):

1. Employed phase: for every source i pick a random dimension j and a random partner k != i and make
   ``v_ij = x_ij + U(-1, 1) (x_ij - x_kj)`` (Eq. 12), other components unchanged; keep v if it is strictly
   better (greedy selection), otherwise increase the trial counter of i.
2. Onlooker phase: SN onlookers choose sources by roulette wheel with probability p_i = fit_i / sum fit
   (Eq. 13) on the fitness of Eq. 14, then search around the chosen source exactly as in step 1.
3. Scout phase: the source with the largest trial counter, if that counter exceeds ``limit = SN * D``
   (Akay & Karaboga; paper ref. [14]), is abandoned and replaced by a uniform random point. At most one
   scout per iteration, as in Karaboga's code.

The best point ever evaluated is remembered by the framework (``Search``), so step "record the best" is implicit.

Fitness (Eq. 14): ``fit = 1/(1+f)`` for ``f >= 0`` and ``1 + |f|`` for ``f < 0``. The paper prints the two
cases the wrong way round (it would give a pole at f = -1 and reward larger costs); this is the version of
Karaboga's code (``CalculateFitness.m``).

Vectorisation (documented because it differs slightly from Karaboga's sequential loops):

* Employed phase: all SN candidates are generated from the sources as they stand at the start of the phase
  (partners k are taken from that snapshot, not from sources already updated earlier in the same phase) and
  evaluated in one batch; greedy selection is then applied per source.
* Onlooker phase: the SN roulette choices are drawn first (independent spins with the probabilities of
  Eq. 13, computed after the employed phase), the SN candidates are generated from the current sources and
  evaluated in one batch, and greedy selection is applied in onlooker order. When several onlookers chose
  the same source, each candidate is compared with the source *as updated by the earlier onlookers*: the
  source ends as the best of itself and all its candidates, and every candidate that fails to improve it
  increases its trial counter by one (as each failing onlooker does in Karaboga's code).
* Karaboga's onlookers use ``prob = 0.9 fit/max(fit) + 0.1`` with a sweeping acceptance loop; here the
  paper's Eq. 13 roulette wheel is used instead.

Candidates leaving the box are clipped onto the bound (as ``ABC.m`` does). The initial sources are uniform
in the box, with source 0 replaced by ``x0`` when given. Per iteration ABC spends N evaluations (SN employed,
SN onlookers) plus one per scout. If N is odd SN = floor(N/2); SN is at least 2 so that a partner exists.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .base import Optimizer, Search, register


def abc_fitness(cost: ArrayLike) -> NDArray:
    """ABC fitness of costs (paper Eq. 14, corrected): 1/(1+f) if f >= 0, else 1 + |f|. Larger is better."""
    f = np.asarray(cost, dtype=float)
    return np.where(f >= 0, 1.0 / (1.0 + np.abs(f)), 1.0 + np.abs(f))


@dataclass
class _HiveState:
    x: NDArray  # (SN, D) food sources
    f: NDArray  # (SN,) their costs
    trial: NDArray  # (SN,) trials without improvement


@register
class ABC(Optimizer):
    """Artificial Bee Colony with SN = N/2 food sources; options ``limit`` (default SN*D)."""

    name = "abc"

    def __init__(self, population: int = 20, iterations: int = 50, **options: Any):
        super().__init__(population, iterations, **options)
        self.sources = max(2, self.population // 2)
        self.limit_option = options.get("limit")

    def _initialize(self, run: Search, x0: NDArray | None) -> _HiveState:
        x = run.uniform(self.sources)
        if x0 is not None:
            x[0] = x0
        state = _HiveState(x=x, f=np.full(self.sources, np.inf), trial=np.zeros(self.sources, dtype=np.int64))
        state.f = run.evaluate(x)
        return state

    def _neighbours(self, run: Search, x: NDArray, chosen: NDArray) -> NDArray:
        """Eq. 12 candidates for the sources ``chosen`` (indices into x): one random dimension each,
        partner k != i from the same snapshot x, step U(-1, 1) (x_ij - x_kj), clipped into the box."""
        sn, d = x.shape
        m = chosen.size
        j = run.rng.integers(0, d, size=m)
        k = run.rng.integers(0, sn - 1, size=m)
        k = k + (k >= chosen)  # uniform over the other SN - 1 sources
        phi = run.rng.uniform(-1.0, 1.0, size=m)
        v = x[chosen].copy()
        rows = np.arange(m)
        v[rows, j] = x[chosen, j] + phi * (x[chosen, j] - x[k, j])
        return np.clip(v, run.problem.lower, run.problem.upper)

    @staticmethod
    def _greedy(state: _HiveState, chosen: NDArray, v: NDArray, fv: NDArray) -> None:
        """Greedy selection in order; a source chosen twice is compared with its already-updated value."""
        for i, cand, fc in zip(chosen, v, fv, strict=True):
            if fc < state.f[i]:
                state.x[i], state.f[i], state.trial[i] = cand, fc, 0
            else:
                state.trial[i] += 1

    def _step(self, run: Search, state: _HiveState) -> None:
        sn, d = state.x.shape
        limit = int(self.limit_option) if self.limit_option is not None else sn * d
        # employed bees: one candidate per source, one batch
        employed = np.arange(sn)
        v = self._neighbours(run, state.x, employed)
        self._greedy(state, employed, v, run.evaluate(v))
        # onlooker bees: roulette wheel on Eq. 13/14, one batch
        fit = abc_fitness(state.f)
        onlookers = run.rng.choice(sn, size=sn, p=fit / fit.sum())
        v = self._neighbours(run, state.x, onlookers)
        self._greedy(state, onlookers, v, run.evaluate(v))
        # scout bee: at most one abandoned source per iteration
        i = int(np.argmax(state.trial))
        if state.trial[i] > limit:
            new = run.uniform(1)
            state.f[i] = run.evaluate(new)[0]
            state.x[i], state.trial[i] = new[0], 0
