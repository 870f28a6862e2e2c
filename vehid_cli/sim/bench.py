"""The damper on a virtual test bench: the bench adapter of the compiled kernel (``prescribed.integrate_lanes``: every
candidate of a batch at once through the model's batch law; ``integrate_bench``, the scalar law, is the reference).

The motion x, v is prescribed; models with a control input get the command delayed per candidate
(``delayed_controls``) and a backlash candidate sees the piston's motion through the play. The kernel
integrates at dt / substeps with every input linear between samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..core.jit import cached_njit
from ..models.damper import N_FRONT, DamperModel, play
from .prescribed import integrate_bench, integrate_lanes


def delayed_controls(t: NDArray, u: NDArray, v: NDArray, delays: NDArray, out: NDArray | None = None) -> NDArray:
    """(P, n, 2): the delayed command and the direction of its latest change (1 rising, 0 falling), per candidate
    (written into `out` when given: any (P, n, 2) float64 view, e.g. of the kernel's lanes).

    Each change of the command u (n,), between samples i-1 and i, takes effect at t_i + tau with tau the
    candidate's delay (P, 4: DELAYS order) for the change's direction and the stroke (sign of v) it happens in.
    A change is laid on the sample grid as a one-sample ramp that starts at its exact effective time, so the
    delayed command (and the cost) moves continuously with tau instead of in whole samples. A change that would
    overtake a later one is merged into it. Commands that change at most samples (not steps) are shifted by
    interpolation instead.
    """
    delays = np.atleast_2d(delays)
    P, n = delays.shape[0], t.size
    dt = float(t[1] - t[0])
    change = np.diff(u, prepend=u[0])
    rising = change > 0
    which = np.where(v > 0, 2, 0) + np.where(rising, 0, 1)  # tau_comp_rise, tau_comp_fall, tau_reb_rise, ..._fall
    moved = np.flatnonzero(change != 0)
    out = np.empty((P, n, 2)) if out is None else out
    if moved.size == 0:
        out[:, :, 0], out[:, :, 1] = u[0], 1.0  # no change: the initial command throughout, rising
        return out
    if moved.size > n // 10:  # a continuous command: shift it by its local delay
        for p in range(P):
            tau = delays[p, which]
            out[p, :, 0] = np.interp(t - tau, t, u)
            out[p, :, 1] = _hold(np.where(change > 0, 1.0, np.where(change < 0, 0.0, np.nan)))
        return out
    steps = (t[moved], change[moved], rising[moved].astype(float), which[moved])
    if np.all(delays == delays[:1]):  # the same delays for every candidate (they are not fitted): ramped once
        _ramps(t, *steps, delays[:1], float(u[0]), dt, out[:1].transpose(1, 2, 0))
        out[1:] = out[0]
        return out
    _ramps(t, *steps, delays, float(u[0]), dt, out.transpose(1, 2, 0))
    return out


@cached_njit(error_model="numpy")
def _ramps(t, at, jumps, rising, which, delays, u0, dt, out):  # pragma: no cover - compiled
    """Each candidate p's delayed command out[k, 0, p] (the initial command u0 plus each jump as a one-sample ramp
    from its effective time at + delay - dt, never before an earlier change's: in order) and the direction of the
    latest change completed by each sample out[k, 1, p] (1, rising, before the first): as
    ``level += jump * clip((t - e) / dt, 0, 1)`` and ``searchsorted(effective + dt, t, 'right') - 1`` compute
    them, number for number. `out` (n, 2, P) is the kernel's lanes (the candidates last): time outside, the
    candidates inside, so each sample's row is written whole (candidate by candidate it had been a strided store per
    sample: 0.25 -> 0.18 ms for 20 candidates on the sawtooth with steps).

    Only the samples around a change's effective time (from the one before it to the second after its end, for any
    candidate) are computed; every other sample repeats the row before it, which is what the walk would compute
    there (no change begins, ends or is under way: the same level and direction). A sawtooth's few steps leave most
    of a record's samples such copies: the command of 20 candidates 2.2x faster (310 -> 135-168 us, one process).
    The windows rest on t increasing strictly (the bench's grid always does); times that stand still or go back
    are walked sample by sample, as before."""
    n, m, P = t.shape[0], at.shape[0], delays.shape[0]
    effective = np.empty((P, m))
    active = np.zeros(n, np.bool_)  # samples where some candidate's command or direction may change
    active[0] = True
    for k in range(1, n):
        if not t[k] > t[k - 1]:  # not strictly increasing: every sample walked
            active[:] = True
            break
    for p in range(P):
        for i in range(m):
            effective[p, i] = at[i] - dt + delays[p, which[i]]
            if i > 0:
                effective[p, i] = max(effective[p, i], effective[p, i - 1])  # np.maximum.accumulate
            e = effective[p, i]
            # it begins at the first sample after e and ends (its direction too) at about the first at e + dt; a
            # sample of margin on each side (the ramp's end is tested as (t - e) / dt >= 1, not t >= e + dt)
            lo = np.searchsorted(t, e, "right") - 1
            hi = np.searchsorted(t, e + dt, "left") + 2
            for k in range(max(lo, 0), min(hi, n - 1) + 1):
                active[k] = True
    # One walk over the samples (each written once, not once per change): before sample k the changes [0, on) have
    # begun (t_k > effective) and [0, done) have ended ((t_k - effective) / dt >= 1; effective never decreases, so
    # both are prefixes); the level is the initial command plus the ended jumps, added in their order, then the
    # ramps under way, in theirs: the sums above, term for term (the changes not yet begun add nothing). The
    # direction walks effective (and t, neither decreases) with the completed changes' count.
    level = np.full(P, u0)
    on, done, ended = np.zeros(P, np.int64), np.zeros(P, np.int64), np.zeros(P, np.int64)
    for k in range(n):
        if not active[k]:  # nothing begins, ends or is under way: the row before
            for p in range(P):
                out[k, 0, p] = out[k - 1, 0, p]
            for p in range(P):
                out[k, 1, p] = out[k - 1, 1, p]
            continue
        for p in range(P):
            e = effective[p]
            while on[p] < m and t[k] > e[on[p]]:
                on[p] += 1
            while done[p] < on[p] and not (t[k] - e[done[p]]) / dt < 1.0:
                level[p] += jumps[done[p]]
                done[p] += 1
            value = level[p]
            for i in range(done[p], on[p]):
                value += jumps[i] * ((t[k] - e[i]) / dt)
            out[k, 0, p] = value
            while ended[p] < m and e[ended[p]] + dt <= t[k]:
                ended[p] += 1
            out[k, 1, p] = rising[ended[p] - 1] if ended[p] > 0 else 1.0


def _hold(flags: NDArray) -> NDArray:
    """Forward-fill NaNs (samples without a change keep the last direction; rising before any)."""
    out = flags.copy()
    last = 1.0
    for k in range(out.size):
        if np.isnan(out[k]):
            out[k] = last
        else:
            last = out[k]
    return out


def refine(t: NDArray, road: NDArray, substeps: int, time_axis: int = 1) -> NDArray:
    """Bench channels on the grid t (its axis `time_axis`: (P, n, k) by default), resampled at dt / substeps, linear
    between the samples."""
    if substeps <= 1:
        return road
    a = np.moveaxis(road, time_axis, 0)
    flat = a.reshape(a.shape[0], -1)
    fine = np.linspace(t[0], t[-1], (t.size - 1) * substeps + 1)
    out = np.empty((fine.size, flat.shape[1]))
    for c in range(flat.shape[1]):
        out[:, c] = np.interp(fine, t, flat[:, c])
    return np.moveaxis(out.reshape((fine.size, *a.shape[1:])), 0, time_axis)


@dataclass(frozen=True)
class BenchForces:
    """The force of a batch of candidate dampers on one bench history, and whether each stayed finite."""

    t: NDArray  # (n,) [s]
    force: NDArray  # (P, n) [N]
    stable: NDArray  # (P,) bool


def simulate_damper(
    model: DamperModel,
    rows: NDArray,
    t: NDArray,
    x: NDArray,
    v: NDArray,
    u: NDArray | None = None,
    substeps: int = 1,
    method: str = "rk4",
    reference: bool = False,
) -> BenchForces:
    """Force of P candidates (rows (P, n_par) in `model.layout` order) on the bench history x, v, u.

    The kernel integrates at dt / substeps with every input linear between samples; the force is
    returned at the bench's samples. A candidate whose internal states blow up gets NaN forces and
    stable = False. The model's batch law runs every candidate at once (``prescribed.integrate_lanes``);
    `reference` runs its scalar law one candidate after the other instead (``integrate_bench``: the same
    forces bit for bit, several times slower; for tests and the benchmark's anchor).
    """
    rows = np.atleast_2d(np.asarray(rows, dtype=float))
    if reference:
        return _simulate_reference(model, rows, t, x, v, u, substeps)
    P, n = rows.shape[0], t.size
    dt = float(t[1] - t[0])
    u = np.zeros(n) if u is None else np.asarray(u, dtype=float)
    x, v = np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(v, dtype=float)
    road = np.empty((n, 4 if model.uses_control else 2, P))  # the candidates last: the kernel's lanes
    _spread(road, x, v)
    for r in np.flatnonzero(rows[:, 2] > 0):  # backlash: the piston's motion through the play
        road[:, 0, r], road[:, 1, r] = play(x, v, rows[r, 2])
    if model.uses_control:
        delayed_controls(t, u, v, rows[:, N_FRONT : N_FRONT + 4], out=road[:, 2:, :].transpose(2, 0, 1))
    road = refine(t, road, substeps, time_axis=0)  # finer integration of the same inputs
    z0 = np.zeros((model.n_states, P))
    if model.uses_control:
        z0[-1] = u[0]  # the lagged input starts at the command
    if model.name in ("bouc_wen", "generalized_bouc_wen"):
        z0[0] = x[0]  # Bouc-Wen internal displacement starts where the piston is: no initial spring force
    with np.errstate(all="ignore"):
        forces = integrate_lanes(model.lanes, rows, road, dt / substeps, z0, model.scratch)
    return _checked(t, forces[:, ::substeps])


@cached_njit()
def _spread(road, x, v):  # pragma: no cover - compiled
    """road[:, 0, p] = x and road[:, 1, p] = v for every candidate p, as a NumPy broadcast assignment writes them
    (its inner loops one row of 20 candidates long): 79 -> 58 us for 3001 samples, one process."""
    for k in range(road.shape[0]):
        for p in range(road.shape[2]):
            road[k, 0, p] = x[k]
        for p in range(road.shape[2]):
            road[k, 1, p] = v[k]


def _checked(t: NDArray, force: NDArray) -> BenchForces:
    """The forces (P, n) with every candidate that did not stay finite NaN throughout (a NaN or an infinity
    anywhere makes its row's largest or smallest value not finite: two reductions, no array of flags)."""
    stable = np.isfinite(force.max(axis=1)) & np.isfinite(force.min(axis=1))
    if stable.all():
        return BenchForces(t=t, force=np.ascontiguousarray(force), stable=stable)
    return BenchForces(t=t, force=np.where(stable[:, None], force, np.nan), stable=stable)


def _simulate_reference(
    model: DamperModel, rows: NDArray, t: NDArray, x: NDArray, v: NDArray, u: NDArray | None, substeps: int
) -> BenchForces:
    """``simulate_damper`` through the model's scalar law, one candidate after the other (the reference path)."""
    P, n = rows.shape[0], t.size
    dt = float(t[1] - t[0])
    u = np.zeros(n) if u is None else np.asarray(u, dtype=float)
    x, v = np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(v, dtype=float)
    channels = 4 if model.uses_control else 2
    road = np.empty((P, n, channels))
    road[:, :, 0], road[:, :, 1] = x, v
    for r in np.flatnonzero(rows[:, 2] > 0):  # backlash: the piston's motion through the play
        road[r, :, 0], road[r, :, 1] = play(x, v, rows[r, 2])
    if model.uses_control:
        road[:, :, 2:] = delayed_controls(t, u, v, rows[:, N_FRONT : N_FRONT + 4])
    road = refine(t, road, substeps)  # finer integration of the same inputs
    z0 = np.zeros((P, model.n_states))
    if model.uses_control:
        z0[:, -1] = u[0]  # the lagged input starts at the command
    if model.name in ("bouc_wen", "generalized_bouc_wen"):
        z0[:, 0] = x[0]  # Bouc-Wen internal displacement starts where the piston is: no initial spring force
    with np.errstate(all="ignore"):
        forces = integrate_bench(model.law, rows, road, dt / substeps, z0)
    return _checked(t, forces[:, ::substeps, 0])
