"""Constriction-factor particle swarm optimisation (CPSO), Gökdağ 2015 Eq. 10–11 after Clerc & Kennedy (2002).

Velocity and position update per particle i and dimension j (paper Eq. 10–11)::

    v_ij <- chi * (v_ij + c1 R1 (p_ij - x_ij) + c2 R2 (p_gj - x_ij))
    x_ij <- x_ij + v_ij

with c1 = c2 = 2.05, phi = c1 + c2 = 4.1 > 4 and the constriction factor
chi = 2 / |2 - phi - sqrt(phi^2 - 4 phi)| = 0.7298 (Clerc & Kennedy 2002, Eq. 4.15; paper section 2.3).
R1 and R2 are drawn uniform in [0, 1) independently per particle and per dimension; the topology is the
global best (p_g is the best personal best of the whole swarm). The update is synchronous: the whole swarm
moves, then all N particles are evaluated in one batch, then personal and global bests are updated.

Choices the paper leaves open (documented here because they change results):

* Initial positions: uniform in the box; particle 0 is replaced by ``x0`` when one is given.
* Initial velocities: ``v0 = (u - x0) / 2`` with ``u`` a second uniform point in the box (the SPSO-2007
  rule of Clerc). Each component lies in ``±(ub - lb)/2`` and the first undamped move stays inside the box.
* Velocity clamp: ``|v_j| <= vmax_j = (ub_j - lb_j)`` (option ``vmax_fraction``, default 1.0). With
  constriction a clamp is not needed for convergence; a full-range clamp only stops pathological excursions.
* Bounds: a position leaving the box is clipped onto the violated bound and that velocity component is set
  to zero ("absorbing wall"), so the particle does not keep pushing against the wall.
* Personal bests are replaced only on strict improvement; the global best is the best personal best.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .base import Optimizer, Search, register


def constriction_factor(c1: float = 2.05, c2: float = 2.05) -> float:
    """Clerc–Kennedy constriction chi = 2 / |2 - phi - sqrt(phi^2 - 4 phi)|, phi = c1 + c2 > 4 (paper Eq. 10)."""
    phi = c1 + c2
    if phi <= 4.0:
        raise ValueError(f"constriction needs phi = c1 + c2 > 4, got {phi}")
    return 2.0 / abs(2.0 - phi - math.sqrt(phi * phi - 4.0 * phi))


@dataclass
class _SwarmState:
    x: NDArray  # (N, D) positions
    v: NDArray  # (N, D) velocities
    p: NDArray  # (N, D) personal best positions
    fp: NDArray  # (N,) personal best costs
    vmax: NDArray  # (D,)


@register
class CPSO(Optimizer):
    """Constriction PSO with a global-best topology (paper Eq. 10–11); options ``c1``, ``c2``, ``vmax_fraction``."""

    name = "cpso"

    def __init__(self, population: int = 20, iterations: int = 50, **options: Any):
        super().__init__(population, iterations, **options)
        self.c1 = float(options.get("c1", 2.05))
        self.c2 = float(options.get("c2", 2.05))
        self.chi = constriction_factor(self.c1, self.c2)
        self.vmax_fraction = float(options.get("vmax_fraction", 1.0))

    def _initialize(self, run: Search, x0: NDArray | None) -> _SwarmState:
        lo, hi = run.problem.lower, run.problem.upper
        x = run.uniform(self.population)
        if x0 is not None:
            x[0] = x0
        v = (run.uniform(self.population) - x) / 2.0
        vmax = self.vmax_fraction * (hi - lo)
        state = _SwarmState(x=x, v=v, p=x.copy(), fp=np.full(self.population, np.inf), vmax=vmax)
        state.fp = run.evaluate(x)
        return state

    def _step(self, run: Search, state: _SwarmState) -> None:
        lo, hi = run.problem.lower, run.problem.upper
        n, d = state.x.shape
        g = state.p[int(np.argmin(state.fp))]
        r1 = run.rng.random((n, d))
        r2 = run.rng.random((n, d))
        v = self.chi * (state.v + self.c1 * r1 * (state.p - state.x) + self.c2 * r2 * (g - state.x))  # Eq. 10
        v = np.clip(v, -state.vmax, state.vmax)
        x = state.x + v  # Eq. 11
        outside = (x < lo) | (x > hi)
        x = np.clip(x, lo, hi)
        v[outside] = 0.0
        state.x, state.v = x, v
        f = run.evaluate(x)
        better = f < state.fp
        state.p[better] = x[better]
        state.fp[better] = f[better]
