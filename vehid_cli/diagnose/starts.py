"""The screening of a candidate's starts: a few damped Gauss-Newton steps from each of its starts (values of its shape,
and where its force is not proportional to them, its strength parameters), all starts batched, to pick the one its fit
(attribution.candidate_fit) polishes; a known parameter's two starts (its configured value, its earlier estimate)
compared by their costs alone (`lower_start`)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from ..optimizers.base import Problem

SCREEN_STEPS = 3  # damped Gauss-Newton steps from each start before they are compared
PROBE = 1e-4  # difference step of the screening's Gauss-Newton step, as a fraction of each unknown's range
SECANT = True  # after its first step a start's car columns follow Broyden's update (only the candidate's differenced)


def screen_starts(
    problem: Problem, x0: NDArray, starts: Sequence[dict[str, float]], shape: Sequence[str] = (),
    strength: Sequence[str] = (), null: dict[str, float] | None = None, linear: bool = False, base: int | None = None,
    car: NDArray | None = None,
) -> NDArray:  # fmt: skip
    """The best start of a candidate (attribution.Candidate): its `starts` (values of some unknowns) applied to x0,
    then SCREEN_STEPS damped Gauss-Newton steps from each over every unknown but the `shape` ones (the car moves back
    where the declared fit bent it to mimic the effect), all starts in one batched evaluation per Jacobian and per
    trial step; the point with the lowest cost. The first `base` unknowns are the current fit's (the car's), the
    others the candidate's.

    The steps' Jacobians (SECANT): the columns of the candidate's own unknowns by forward differences at every step
    (where the effect's nonlinearity is); the car's from `car` (R, base), the current fit's Jacobian, exact where the
    effect has no force (else by forward differences at the first step), then by Broyden's update along each accepted
    step. They only steer: every step is kept only where the exact cost falls, and the candidate's fit that follows
    (trust region, exact forward differences) decides the LR. Simulated once: the starts' costs are their first
    Jacobian's centre rows, a trial's residual is its next Jacobian's centre; a start whose last step was rejected
    has not moved (its next step would be the same) and is not stepped again; the starts of an effect whose force
    is proportional to its `strength` unknowns (`linear`) with those at their `null` (default zero) have no force,
    so with the same car they share their response and its derivatives along the car's unknowns."""
    names = list(problem.names)
    lo, hi = problem.lower, problem.upper
    P = _start_points(problem, x0, starts)
    free = [j for j, n in enumerate(names) if n not in shape]
    at_null = [(names.index(n), (null or {}).get(n, 0.0)) for n in strength if n in names]
    base = len(names) if base is None else base
    h = PROBE * (hi - lo)
    cost = np.full(len(P), np.inf)
    resid: list[NDArray | None] = [None] * len(P)  # the residual at each start's point, once known
    last = _first_jacobians(P, car, free, base)  # point, residual, Jacobian of each start's last step
    moved = np.ones(len(P), dtype=bool)  # starts whose point changed since their last Jacobian
    for _ in range(SCREEN_STEPS):
        rows: list[NDArray] = []
        at: dict[int, tuple[int, dict[int, int]]] = {}  # start -> its centre row (-1: known), its rows by unknown
        shared: dict[tuple, tuple[int, dict[int, int]]] = {}  # force-free starts' centre and car rows, by car values
        for i in np.flatnonzero(moved):
            x = P[i]
            secant = SECANT and last[i] is not None  # the car's columns by Broyden's update: the candidate's only
            off = linear and at_null and all(x[j] == v for j, v in at_null)
            key = (secant, x[:base].tobytes()) if off else None
            if key is not None and key in shared:
                centre, car_rows = shared[key]
            else:
                centre = -1 if resid[i] is not None else len(rows)
                if centre >= 0:
                    rows.append(x)
                car_rows = {} if secant else {j: _row(rows, x, j, h, hi) for j in free if j < base}
                if key is not None:
                    shared[key] = (centre, car_rows)
            at[i] = (centre, {**car_rows, **{j: _row(rows, x, j, h, hi) for j in free if j >= base}})
        if not at:
            break
        with np.errstate(all="ignore"):
            C, R = problem.residuals(np.array(rows)) if rows else (np.empty(0), np.empty((0, 0)))
        trial = P.copy()
        for i, (centre, by) in at.items():
            x = P[i]
            if centre >= 0:
                resid[i] = R[centre]
                cost[i] = C[centre] if np.isfinite(C[centre]) else np.inf
            r0 = resid[i]
            D = _jacobian(R, rows, by, x, r0, free, last[i], hi - lo)
            if not (np.all(np.isfinite(D)) and np.all(np.isfinite(r0))):
                continue
            last[i] = (x.copy(), r0, D)
            JtJ = D.T @ D
            step = np.linalg.lstsq(JtJ + 1e-3 * np.diag(np.diag(JtJ)), -D.T @ r0, rcond=None)[0]
            trial[i, free] = np.clip(x[free] + step, lo[free], hi[free])
        tried = np.flatnonzero(np.any(trial != P, axis=1))
        moved[:] = False
        if tried.size == 0:
            break
        with np.errstate(all="ignore"):
            c, r = problem.residuals(trial[tried])
        for m, i in enumerate(tried):
            if np.isfinite(c[m]) and c[m] < cost[i]:
                P[i], cost[i], resid[i], moved[i] = trial[i], c[m], r[m], True
    return P[int(np.argmin(cost))]


def lower_start(problem: Problem, x0: NDArray, prior: dict[str, float]) -> NDArray:
    """x0 or x0 with the `prior` values (a known parameter's estimate in an earlier round), whichever costs less (one
    batch of two evaluations): a single unknown's fit needs no screening steps to choose its start
    (`screen_starts`: three damped Gauss-Newton steps from each, the cost of three Jacobians)."""
    warm = x0.copy()
    for n, v in prior.items():
        j = problem.names.index(n)
        warm[j] = np.clip(v, problem.lower[j], problem.upper[j])
    with np.errstate(all="ignore"):
        costs = problem.cost(np.vstack([x0, warm]))
    return warm if np.isfinite(costs[1]) and costs[1] < costs[0] else x0


def _jacobian(R: NDArray, rows: list[NDArray], by: dict[int, int], x: NDArray, r0: NDArray, free: list[int],
              last: tuple[NDArray, NDArray, NDArray] | None, width: NDArray) -> NDArray:  # fmt: skip
    """(R, len(free)) a start's Jacobian at x (residual r0): forward differences from the rows `by` unknown (of the
    batch `rows`, residuals R), the columns not differenced by Broyden's update of its `last` step's."""
    with np.errstate(over="ignore", invalid="ignore"):  # an unstable trial point: inf, not a printed warning
        diff = {j: (R[k] - r0) / (rows[k][j] - x[j]) for j, k in by.items()}
        if len(diff) == len(free) or last is None:
            return np.stack([diff[j] for j in free], 1)
        xp, rp, Jp = last
        D = broyden(Jp, (x - xp)[free], r0 - rp, width[free])
        for m, j in enumerate(free):
            if j in diff:
                D[:, m] = diff[j]
        return D


def _first_jacobians(P: NDArray, car: NDArray | None, free: list[int], base: int) -> list:
    """Each start's (point, residual, Jacobian) to update at its first step: the current fit's Jacobian `car` in the
    car's columns (SECANT; the candidate's own filled at the step), else None (forward differences throughout)."""
    if not SECANT or car is None:
        return [None] * len(P)
    first = np.zeros((car.shape[0], len(free)))
    for m, j in enumerate(free):
        if j < base:
            first[:, m] = car[:, j]
    return [(x.copy(), np.zeros(car.shape[0]), first) for x in P]


def _start_points(problem: Problem, x0: NDArray, starts: Sequence[dict[str, float]]) -> NDArray:
    """(S, D) x0 with each start's values (of the unknowns it names) clipped into the box."""
    names = list(problem.names)
    lo, hi = problem.lower, problem.upper
    points = []
    for s in starts:
        x = np.array(x0, dtype=float)
        for k, v in s.items():
            if k in names:
                j = names.index(k)
                x[j] = np.clip(v, lo[j], hi[j])
        points.append(x)
    return np.array(points)


def _row(rows: list[NDArray], x: NDArray, j: int, h: NDArray, hi: NDArray) -> int:
    """Append x stepped by h along unknown j (inward at the upper bound) to `rows`; its index."""
    q = x.copy()
    q[j] = x[j] + h[j] if x[j] + h[j] <= hi[j] else x[j] - h[j]
    rows.append(q)
    return len(rows) - 1


def broyden(J: NDArray, dx: NDArray, dr: NDArray, width: NDArray) -> NDArray:
    """Broyden's rank-one update of a Jacobian J (R, D) along a step dx (D,) that changed the residuals by dr (R,),
    in box-width units (the unknowns' scales differ by orders of magnitude): the least change of J that reproduces the
    step's secant, so that columns not differenced again follow the response along the step."""
    du = dx / width
    nu = float(du @ du)
    if not (nu > 0 and np.all(np.isfinite(dr))):
        return J.copy()
    return J + np.outer(dr - J @ dx, du / width) / nu
