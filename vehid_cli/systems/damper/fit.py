"""Damper identification (Fleps-Dezasse section 4): the cost J, bounded fits and the real-time check (the
step-by-step procedure is `systems/damper.py`).

J (Eq. 7) is the mean squared force error over the variance of the measured force. A candidate whose
simulation blows up gets a finite penalty larger than the initial cost, as in the paper, so an
optimizer (Nelder–Mead by default, as the paper's Simplex, or any of the project's) never stops on it.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from ...core.result import Result
from ...models.bench import BenchHistory
from ...models.damper import MODELS, DamperModel, play
from ...models.effects import bench_effect_rows, bench_lag_state
from ...optimizers import Problem, get_optimizer
from ...sim.bench import BenchForces, refine, simulate_damper
from ...sim.prescribed import integrate_bench

PENALTY_FACTOR = 10.0  # an unstable candidate costs this many times the initial J (at least 10)


def cost_J(measured: NDArray, simulated: NDArray) -> NDArray:
    """Eq. 7: mean squared error over the variance of the measured force (mean removed); (..., n) -> (...)."""
    measured = np.asarray(measured, dtype=float)
    mse, var = np.mean((measured - simulated) ** 2, axis=-1), np.var(measured)
    if not var > 0:  # a constant measured force (no motion, a zero force law): J is undefined, not a division by 0
        return np.full(np.shape(mse), np.nan)
    return mse / var


@dataclass(frozen=True)
class DamperSpec:
    """A damper model with every parameter valued: the row the kernel runs, by name; plus library effects
    around it on the bench (``effects``, their parameters valued as ``<effect>.<param>``, e.g.
    ``hysteresis.alpha``; see models/effects/law.py ``bench_law``)."""

    model: str
    values: Mapping[str, float]
    table_shape: tuple[int, ...] = ()
    effects: tuple[str, ...] = ()

    @property
    def damper(self) -> DamperModel:
        return MODELS[self.model]

    @property
    def names(self) -> tuple[str, ...]:
        return self.damper.layout(self.table_shape)

    def row(self) -> NDArray:
        missing = [n for n in self.names if n not in self.values]
        if missing:
            raise KeyError(f"{self.model}: no value for {missing}")
        return np.array([float(self.values[n]) for n in self.names])

    def rows(self, unknowns: Sequence[str], X: NDArray) -> NDArray:
        """Rows for a batch of candidates: the spec's values with `unknowns` replaced by the columns of X
        (effect parameters among the unknowns are skipped: they are not in the model's row)."""
        base = self.row()
        out = np.repeat(base[None, :], len(X), axis=0)
        index = {n: i for i, n in enumerate(self.names)}
        for j, name in enumerate(unknowns):
            if name in index:
                out[:, index[name]] = X[:, j]
        return out

    def effect_values(self, unknowns: Sequence[str] = (), X: NDArray | None = None) -> dict[str, dict]:
        """The effects' parameters (base names) for a batch: the spec's values, `unknowns` from X's columns."""
        out: dict[str, dict] = {e: {} for e in self.effects}
        for key, value in self.values.items():
            effect, _, param = key.partition(".")
            if effect in out:
                out[effect][param] = value
        for j, name in enumerate(unknowns):
            effect, _, param = name.partition(".")
            if effect in out:
                out[effect][param] = X[:, j]
        return out

    def with_values(self, values: Mapping[str, float]) -> DamperSpec:
        return DamperSpec(self.model, {**self.values, **values}, self.table_shape, self.effects)

    def with_effects(self, effects: Sequence[str], values: Mapping[str, float]) -> DamperSpec:
        """This damper with more bench effects (and their parameter values)."""
        more = tuple(e for e in effects if e not in self.effects)
        return DamperSpec(self.model, {**self.values, **values}, self.table_shape, self.effects + more)

    def simulate_batch(
        self, unknowns: Sequence[str], X: NDArray, history: BenchHistory, substeps: int = 1
    ) -> BenchForces:
        """Forces of a batch of candidates (`unknowns` = columns of X) on the history, effects included."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        rows = self.rows(unknowns, X)
        h = history
        if not self.effects:
            return simulate_damper(self.damper, rows, h.t, h.x, h.v, h.u, substeps)
        return _with_effects(self, rows, self.effect_values(unknowns, X), h, substeps)

    def simulate(self, history: BenchHistory, substeps: int = 1) -> NDArray:
        """Force (n,) of this damper on the history."""
        return self.simulate_batch((), np.zeros((1, 0)), history, substeps).force[0]


def _with_effects(spec: DamperSpec, rows: NDArray, effects: dict, h: BenchHistory, substeps: int) -> BenchForces:
    """The declared model's force without its gas part, then the bench effects around it (lag on the damper
    force, parallel effects added, the gas force k1 (x_b - x0) on the piston's motion through the play)."""

    P, n = rows.shape[0], h.t.size
    no_gas = rows.copy()
    no_gas[:, 0] = 0.0
    damper = simulate_damper(spec.damper, no_gas, h.t, h.x, h.v, h.u, substeps)
    road = np.empty((P, n, 4))
    road[:, :, 0], road[:, :, 1], road[:, :, 2] = h.x, h.v, damper.force
    for r in range(P):
        xb = h.x if rows[r, 2] <= 0 else play(np.ascontiguousarray(h.x), np.ascontiguousarray(h.v), rows[r, 2])[0]
        road[r, :, 3] = rows[r, 0] * (xb - rows[r, 1])
    eset = bench_effect_rows(effects, P)
    dt = float(h.t[1] - h.t[0])
    road = refine(h.t, road, substeps)  # the effects' states at the model's step
    z0 = np.zeros((P, max(eset.n_z, 1)))
    lag = bench_lag_state(eset)
    if lag is not None:
        z0[:, lag] = damper.force[:, 0]  # the lagged force starts settled
    with np.errstate(all="ignore"):
        force = integrate_bench(eset.law, eset.rows, road, dt / substeps, z0)
    force = force[:, ::substeps, 0]
    stable = damper.stable & np.all(np.isfinite(force), axis=1)
    return BenchForces(t=h.t, force=np.where(stable[:, None], force, np.nan), stable=stable)


@dataclass(frozen=True)
class BenchFit:
    """One fit on a bench run: the values found, J before and after, and the effort."""

    spec: DamperSpec
    unknowns: tuple[str, ...]
    J_initial: float
    J: float
    evaluations: int
    penalised: int
    wall_s: float
    history_evals: NDArray = field(repr=False, default_factory=lambda: np.zeros(0))
    history_cost: NDArray = field(repr=False, default_factory=lambda: np.zeros(0))


def j_problem(
    spec: DamperSpec,
    history: BenchHistory,
    unknowns: Sequence[str],
    bounds: Mapping[str, tuple[float, float]],
    substeps: int = 1,
) -> tuple[Problem, NDArray, float]:
    """J over `unknowns` in their bounds as the optimizers' Problem, the start (the spec's values, clipped into the
    box) and J there; an unstable candidate costs PENALTY_FACTOR x J at the start (at least 10)."""
    if history.force is None:
        raise ValueError("a fit needs a measured force")
    unknowns = tuple(unknowns)
    lower = np.array([bounds[n][0] for n in unknowns], dtype=float)
    upper = np.array([bounds[n][1] for n in unknowns], dtype=float)
    x0 = np.clip(np.array([spec.values[n] for n in unknowns], dtype=float), lower, upper)

    scale = np.sqrt(history.force.size * np.var(history.force))  # J = sum of squared residuals

    def cost_and_residuals(X: NDArray) -> tuple[NDArray, NDArray]:
        run = spec.simulate_batch(unknowns, X, history, substeps)
        residuals = (history.force[None, :] - run.force) / scale
        return np.sum(residuals**2, axis=1), residuals

    def cost(X: NDArray) -> NDArray:
        return cost_and_residuals(X)[0]

    J0 = float(cost(x0[None, :])[0])
    penalty = PENALTY_FACTOR * max(J0 if np.isfinite(J0) else 1.0, 1.0)
    return Problem(lower, upper, cost, residuals=cost_and_residuals, penalty=penalty, names=unknowns), x0, J0


def fit(
    spec: DamperSpec,
    history: BenchHistory,
    unknowns: Sequence[str],
    bounds: Mapping[str, tuple[float, float]],
    *,
    algorithm: str = "nelder-mead",
    budget: int = 2000,
    population: int = 20,
    rng: np.random.Generator,
    substeps: int = 1,
) -> BenchFit:
    """Minimise J over `unknowns` in their bounds, starting from the spec's values, in exactly `budget` model
    evaluations (J at the start is the first) unless the algorithm converges sooner."""
    problem, x0, J0 = j_problem(spec, history, unknowns, bounds, substeps)
    optimizer = get_optimizer(algorithm, population=population, iterations=max(1, budget // population))
    result = optimizer.minimize(problem, rng, budget=max(budget - 1, 1), x0=x0)
    best = spec.with_values(dict(zip(problem.names, result.x, strict=True)))
    return BenchFit(
        spec=best,
        unknowns=tuple(problem.names),
        J_initial=J0,
        J=float(result.cost),
        evaluations=result.evaluations + 1,
        penalised=result.penalised,
        wall_s=result.wall_s,
        history_evals=result.history_evals,
        history_cost=result.history_cost,
    )


# ------------------------------------------------------------------------------------------ real time


@dataclass(frozen=True)
class RealTime(Result):
    """Fixed-step RK4 at the real-time step: stable or not, how fast, and the largest stable step."""

    h5_omit: ClassVar[tuple[str, ...]] = ("model",)  # the group's parent names the model
    json_omit: ClassVar[tuple[str, ...]] = ("model",)

    model: str
    dt: float  # the step checked [s]
    stable: bool
    realtime_factor: float  # simulated time / wall time (> 1: faster than real time)
    largest_stable_dt: float  # [s], from a bisection on the step


def _stable_at(spec: DamperSpec, history: BenchHistory, dt: float) -> tuple[bool, float]:
    t = np.arange(0.0, history.t[-1] - history.t[0], dt) + history.t[0]
    x, v, u = (np.interp(t, history.t, a) for a in (history.x, history.v, history.u))
    start = time.perf_counter()
    run = simulate_damper(spec.damper, spec.row()[None, :], t, x, v, u)
    wall = time.perf_counter() - start
    ok = bool(run.stable[0]) and bool(np.all(np.abs(run.force) < 1e9))
    return ok, (t[-1] - t[0]) / max(wall, 1e-9)


def realtime_check(spec: DamperSpec, history: BenchHistory, dt: float = 1e-3) -> RealTime:
    """Simulate with fixed-step RK4 at `dt`; find the largest stable step between 10 µs and 50 ms."""
    _stable_at(spec, history, dt)  # compile
    stable, rtf = _stable_at(spec, history, dt)
    lo, hi = 1e-5, 5e-2
    if _stable_at(spec, history, hi)[0]:
        largest = hi
    elif not _stable_at(spec, history, lo)[0]:
        largest = 0.0
    else:
        for _ in range(20):  # geometric bisection
            mid = np.sqrt(lo * hi)
            if _stable_at(spec, history, mid)[0]:
                lo = mid
            else:
                hi = mid
        largest = lo
    return RealTime(spec.model, dt, stable, rtf, float(largest))
