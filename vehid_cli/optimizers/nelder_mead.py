"""Bounded Nelder–Mead simplex search (Nelder & Mead 1965; Lagarias et al. 1998), a local method.

Used as a local polisher and to fit damper models. Unlike the population methods it is budget driven: one
``_step`` is one Nelder–Mead iteration (1–2 evaluations, or D for a shrink), and the run ends when the
evaluation budget is spent. ``population`` and ``iterations`` only set the default budget
``population x iterations`` (the same 1000 evaluations as the population methods with the defaults); the
outer iteration cap is ``max_iterations`` (default effectively unlimited), so ``self.iterations`` is set to
that cap in ``__init__`` and ``default_budget`` is overridden to keep ``population x iterations``.

One iteration with the simplex sorted by cost, centroid ``c`` of all but the worst vertex ``x_w``:

* reflect ``x_r = c + rho (c - x_w)``; if it beats the best, try expansion ``x_e = c + chi (x_r - c)``
  and keep the better of the two; if it beats the second-worst, keep ``x_r``;
* otherwise contract: outside ``x_c = c + psi (x_r - c)`` when ``x_r`` beats the worst (accepted if not
  worse than ``x_r``), inside ``x_cc = c - psi (c - x_w)`` otherwise (accepted if better than the worst);
* if the contraction fails, shrink every vertex toward the best: ``x_i = x_b + sigma (x_i - x_b)``; the D
  new vertices are evaluated in one batch.

Choices (documented):

* Coefficients: the adaptive ones of Gao & Han (2012), ``rho = 1, chi = 1 + 2/D, psi = 0.75 - 1/(2D),
  sigma = 1 - 1/D``, which keep the method effective in higher dimensions and equal the standard
  ``1, 2, 0.5, 0.5`` at D = 2. For D = 1 (where sigma would be 0) and with option ``adaptive=False`` the
  standard coefficients are used.
* Bounds: every trial point is clipped into the box before it is evaluated, and the simplex stores the
  clipped point (so stored vertices and costs always agree). Shrink points stay inside by convexity.
* Start: ``x0`` when given, else a uniform random point in the box (from the run's stream).
  Initial simplex: ``x0 + h_j e_j`` with
  ``h_j = initial_step (ub_j - lb_j)`` (default 5 % of the range), taken in the negative direction when the
  positive one would leave the box.
* Restart: when the simplex has collapsed (largest vertex distance from the best, relative to the box
  range, below ``collapse_tol = 1e-10``) and budget remains, a fresh initial simplex is built around the
  best vertex (D new evaluations). With ``restart=False`` the run stops there instead ("converged").

Options: ``adaptive`` (True), ``initial_step`` (0.05), ``collapse_tol`` (1e-10), ``restart`` (True),
``max_iterations`` (10**12).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .base import Optimizer, Search, register


@dataclass
class _SimplexState:
    x: NDArray  # (D+1, D) vertices
    f: NDArray  # (D+1,) costs
    restarts: int = 0


def nelder_mead_coefficients(dim: int, adaptive: bool = True) -> tuple[float, float, float, float]:
    """(reflection, expansion, contraction, shrink): Gao & Han (2012) adaptive ones, or the standard 1, 2, ½, ½."""
    if adaptive and dim >= 2:
        return 1.0, 1.0 + 2.0 / dim, 0.75 - 0.5 / dim, 1.0 - 1.0 / dim
    return 1.0, 2.0, 0.5, 0.5


@register
class NelderMead(Optimizer):
    """Bounded Nelder–Mead with clipping, adaptive coefficients and restarts; budget-driven."""

    name = "nelder-mead"

    def __init__(self, population: int = 20, iterations: int = 50, **options: Any):
        super().__init__(population, iterations, **options)
        self._budget = self.population * self.iterations
        self.iterations = int(options.get("max_iterations", 10**12))
        self.adaptive = bool(options.get("adaptive", True))
        self.initial_step = float(options.get("initial_step", 0.05))
        self.collapse_tol = float(options.get("collapse_tol", 1e-10))
        self.restart = bool(options.get("restart", True))

    def default_budget(self) -> int:
        """population x iterations as given to the constructor (not the outer iteration cap)."""
        return self._budget

    def _simplex_around(self, run: Search, x: NDArray) -> NDArray:
        """The D vertices x + h_j e_j (h_j negative when the positive step would leave the box)."""
        lo, hi = run.problem.lower, run.problem.upper
        h = self.initial_step * (hi - lo)
        h = np.where(x + h > hi, -h, h)
        return np.clip(x + np.diag(h), lo, hi)

    def _initialize(self, run: Search, x0: NDArray | None) -> _SimplexState:
        start = run.start(x0)
        x = np.vstack([start, self._simplex_around(run, start)])
        state = _SimplexState(x=x, f=np.full(len(x), np.inf))
        state.f = run.evaluate(x)
        self._sort(state)
        return state

    @staticmethod
    def _sort(state: _SimplexState) -> None:
        order = np.argsort(state.f, kind="stable")
        state.x, state.f = state.x[order], state.f[order]

    def _collapsed(self, run: Search, state: _SimplexState) -> bool:
        span = run.problem.upper - run.problem.lower
        return bool(np.max(np.abs(state.x[1:] - state.x[0]) / span) < self.collapse_tol)

    def _point(self, run: Search, x: NDArray) -> tuple[NDArray, float]:
        x = np.clip(x, run.problem.lower, run.problem.upper)
        return x, float(run.evaluate(x[None, :])[0])

    def _step(self, run: Search, state: _SimplexState) -> bool | None:
        if self._collapsed(run, state):
            if not self.restart:
                return False
            fresh = self._simplex_around(run, state.x[0])
            state.x[1:], state.f[1:] = fresh, run.evaluate(fresh)
            state.restarts += 1
            self._sort(state)
            return None

        rho, chi, psi, sigma = nelder_mead_coefficients(state.x.shape[1], self.adaptive)
        x, f = state.x, state.f
        centroid = x[:-1].mean(axis=0)
        worst = x[-1]
        xr, fr = self._point(run, centroid + rho * (centroid - worst))
        if fr < f[0]:
            xe, fe = self._point(run, centroid + chi * (xr - centroid))
            x[-1], f[-1] = (xe, fe) if fe < fr else (xr, fr)
        elif fr < f[-2]:
            x[-1], f[-1] = xr, fr
        else:
            if fr < f[-1]:
                xc, fc = self._point(run, centroid + psi * (xr - centroid))
                accepted = fc <= fr
            else:
                xc, fc = self._point(run, centroid - psi * (centroid - worst))
                accepted = fc < f[-1]
            if accepted:
                x[-1], f[-1] = xc, fc
            else:
                shrunk = x[0] + sigma * (x[1:] - x[0])
                x[1:], f[1:] = shrunk, run.evaluate(shrunk)
        self._sort(state)
        return None
