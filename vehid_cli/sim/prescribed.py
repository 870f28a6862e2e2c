"""The prescribed-motion loops of a test bench: the motion is given (the road channels, linear between samples), so
only the force law's internal states are integrated, by RK4. ``integrate_bench`` takes a law of the kernel's
interface, one candidate after the other; ``integrate_lanes`` a law over the whole batch (``lanes``: a damper model's
fast path), the candidates innermost, compiled once per law and cached on disk."""

from __future__ import annotations

import functools

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..core.jit import KeyedCache
from .rk4 import _cache_key


@numba.njit(cache=False, nogil=True)  # takes a force law as argument: not cacheable (numba#9237)
def _bench_rk4(force, params, road, dt, z0, out_f):  # pragma: no cover - compiled
    """RK4 for a strut on a test bench: the motion is prescribed (the road channels, linear between samples),
    so only the force law's internal states are integrated; same law interface as ``_integrate``. Bench laws
    take the motion from the channels (d), so the evaluation at the end of a step is also the first stage
    of the next: four law calls per step."""
    P, n, nu = road.shape
    nz = z0.shape[1]
    ns = out_f.shape[2]
    z, zt = np.empty(nz), np.empty(nz)
    k1, k2, k3, k4 = np.empty(nz), np.empty(nz), np.empty(nz), np.empty(nz)
    d, dm, dd, f = np.empty(nu), np.empty(nu), np.empty(nu), np.empty(ns)
    for p in range(P):
        par = params[p]
        for i in range(nz):
            z[i] = z0[p, i]
        for c in range(nu):
            d[c] = road[p, 0, c]
            dd[c] = (road[p, 1, c] - road[p, 0, c]) / dt
        force(d, dd, z, par, f, k1)
        for i in range(ns):
            out_f[p, 0, i] = f[i]
        for k in range(1, n):
            for c in range(nu):
                dd[c] = (road[p, k, c] - road[p, k - 1, c]) / dt
                dm[c] = 0.5 * (road[p, k - 1, c] + road[p, k, c])
                d[c] = road[p, k, c]
            for i in range(nz):
                zt[i] = z[i] + 0.5 * dt * k1[i]
            force(dm, dd, zt, par, f, k2)
            for i in range(nz):
                zt[i] = z[i] + 0.5 * dt * k2[i]
            force(dm, dd, zt, par, f, k3)
            for i in range(nz):
                zt[i] = z[i] + dt * k3[i]
            force(d, dd, zt, par, f, k4)
            for i in range(nz):
                z[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
            force(d, dd, z, par, f, k1)  # the output at sample k, and the first stage of the next step
            for i in range(ns):
                out_f[p, k, i] = f[i]


def integrate_bench(force, params: ArrayLike, road: ArrayLike, dt: float, z0: ArrayLike, n_s: int = 1) -> NDArray:
    """Forces (P, n, n_s) of P force laws (params rows) on prescribed bench motion road (P, n, n_u) by RK4
    at step dt [s], internal states from z0 (P, n_z)."""
    params = np.ascontiguousarray(np.atleast_2d(params), dtype=float)
    road = np.ascontiguousarray(road, dtype=float)
    z0 = np.ascontiguousarray(z0, dtype=float)
    out = np.empty((road.shape[0], road.shape[1], n_s))
    _bench_rk4(force, params, road, float(dt), z0, out)
    return out


@functools.cache
def lanes_loop(law, nz: int, nu: int, nw: int = 0):
    """The RK4 loop of a batch law ``law(d, z, par, f, zd, w, fresh, read)`` (d (nu, P) the channels, z and zd (nz, P)
    the states and their rates, par (n_par, P) the rows, f (P,) the force, w (nw, P) the law's own scratch, NaN at the
    start and kept from call to call: what it caches; fresh: False when d is the same as at the call before (RK4's
    stage 3 repeats stage 2's channels, the output stage 4's), so what depends on d alone is still in w; read: True
    only at the output call, the stages read zd alone), n_z states, n_u channels and n_w as compile-time constants.

    The time loop is outermost and every stage evaluates the whole batch, so the candidates' independent chains of
    stages overlap in the CPU (and share SIMD registers where the law has no look-up) instead of one candidate's
    latency chain after the other's. Same arithmetic as ``_bench_rk4``, operation for operation: the same forces bit
    for bit. The law is inlined (it is compiled with ``inline="always"``); the loop is cached on disk under a digest
    of this file, the law's file and the sizes (``rk4._cache_key``). Returns run(par, road, dt, z0, out) with road
    (n, nu, P), z0 (nz, P) and out (P, n) the force (each candidate's record contiguous: what the bench returns,
    without a transposing copy; the loop's scattered stores cost nothing measurable)."""

    @numba.njit(nogil=True, error_model="numpy")  # nogil: candidate fits run in parallel threads
    def run(par, road, dt, z0, out):  # pragma: no cover - compiled
        n, P = road.shape[0], road.shape[2]
        z, zs, dm, f = np.empty((nz, P)), np.empty((nz, P)), np.empty((nu, P)), np.empty(P)
        w = np.full((nw, P), np.nan)
        k = np.empty((4, nz, P))  # the stages' rates; k[0] those at the current state (stage 1 of the next step)
        for i in range(nz):
            for p in range(P):
                z[i, p] = z0[i, p]
        for step in range(n):
            d1 = road[step]
            if nz > 0 and step > 0:
                d0 = road[step - 1]
                for c in range(nu):
                    for p in range(P):
                        dm[c, p] = 0.5 * (d0[c, p] + d1[c, p])
                for stage in range(1, 4):
                    h = dt if stage == 3 else 0.5 * dt
                    for i in range(nz):
                        for p in range(P):
                            zs[i, p] = z[i, p] + h * k[stage - 1, i, p]
                    law(d1 if stage == 3 else dm, zs, par, f, k[stage], w, stage != 2, False)
                for i in range(nz):
                    for p in range(P):
                        z[i, p] += dt / 6.0 * (k[0, i, p] + 2.0 * k[1, i, p] + 2.0 * k[2, i, p] + k[3, i, p])
            law(d1, z, par, f, k[0], w, nz == 0 or step == 0, True)  # the output here; stage 1 of the next step
            for p in range(P):
                out[p, step] = f[p]

    key = _cache_key(law, "numpy", nz, nu, nw, loop_files=(__file__, _cache_key.__code__.co_filename))
    if key is not None:
        run._cache = KeyedCache(run.py_func, key)  # numba's on-disk cache, under our own key
    return run


def integrate_lanes(law, params: ArrayLike, road: ArrayLike, dt: float, z0: ArrayLike, n_w: int = 0) -> NDArray:
    """Forces (P, n) of the batch law `law` (``lanes_loop``, n_w rows of scratch) for the rows params (P, n_par) on
    prescribed bench motion road (n, n_u, P: the candidates last) by RK4 at step dt [s], internal states from z0
    (n_z, P)."""
    params = np.ascontiguousarray(np.atleast_2d(params).T, dtype=float)
    road = np.ascontiguousarray(road, dtype=float)
    z0 = np.ascontiguousarray(z0, dtype=float)
    out = np.empty((road.shape[2], road.shape[0]))
    lanes_loop(law, z0.shape[0], road.shape[1], n_w)(params, road, float(dt), z0, out)
    return out
