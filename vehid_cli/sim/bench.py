"""The damper on a virtual test bench: the bench adapter of the compiled kernel (``prescribed.integrate_bench``).

The motion x, v is prescribed; models with a control input get the command delayed per candidate
(``delayed_controls``) and a backlash candidate sees the piston's motion through the play. The kernel
integrates at dt / substeps with every input linear between samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..models.damper import N_FRONT, DamperModel, play
from .prescribed import integrate_bench


def delayed_controls(t: NDArray, u: NDArray, v: NDArray, delays: NDArray) -> NDArray:
    """(P, n, 2): the delayed command and the direction of its latest change (1 rising, 0 falling), per candidate.

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
    out = np.empty((P, n, 2))
    out[:, :, 0], out[:, :, 1] = u[0], 1.0  # before any change takes effect: the initial command
    if moved.size == 0:
        return out
    for p in range(P):
        tau = delays[p, which]
        if moved.size > n // 10:  # a continuous command: shift it by its local delay
            out[p, :, 0] = np.interp(t - tau, t, u)
            out[p, :, 1] = np.where(change > 0, 1.0, np.where(change < 0, 0.0, np.nan))
            out[p, :, 1] = _hold(out[p, :, 1])
            continue
        effective = np.maximum.accumulate(t[moved] - dt + tau[moved])  # the ramp of change i spans one step
        level = np.full(n, u[0])
        for e, jump in zip(effective, change[moved], strict=True):
            level += jump * np.clip((t - e) / dt, 0.0, 1.0)
        out[p, :, 0] = level
        j = np.searchsorted(effective + dt, t, side="right") - 1  # the latest change completed by t
        hit = j >= 0
        out[p, hit, 1] = rising[moved[j[hit]]]
    return out


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


def refine(t: NDArray, road: NDArray, substeps: int) -> NDArray:
    """Bench channels (P, n, k) on the grid t, resampled at dt / substeps, linear between the samples."""
    if substeps <= 1:
        return road
    P, n, k = road.shape
    fine = np.linspace(t[0], t[-1], (n - 1) * substeps + 1)
    out = np.empty((P, fine.size, k))
    for r in range(P):
        for c in range(k):
            out[r, :, c] = np.interp(fine, t, road[r, :, c])
    return out


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
) -> BenchForces:
    """Force of P candidates (rows (P, n_par) in `model.layout` order) on the bench history x, v, u.

    The kernel integrates at dt / substeps with every input linear between samples; the force is
    returned at the bench's samples. A candidate whose internal states blow up gets NaN forces and
    stable = False.
    """
    rows = np.atleast_2d(np.asarray(rows, dtype=float))
    P, n = rows.shape[0], t.size
    dt = float(t[1] - t[0])
    u = np.zeros(n) if u is None else np.asarray(u, dtype=float)
    channels = 4 if model.uses_control else 2
    road = np.empty((P, n, channels))
    road[:, :, 0], road[:, :, 1] = x, v
    for r in np.flatnonzero(rows[:, 2] > 0):  # backlash: the piston's motion through the play
        road[r, :, 0], road[r, :, 1] = play(
            np.ascontiguousarray(x, dtype=float), np.ascontiguousarray(v, dtype=float), rows[r, 2]
        )
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
    force = forces[:, ::substeps, 0]
    stable = np.all(np.isfinite(force), axis=1)
    force = np.where(stable[:, None], force, np.nan)
    return BenchForces(t=t, force=force, stable=stable)
