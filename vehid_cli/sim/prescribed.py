"""The prescribed-motion loop of a test bench: the motion is given (the road channels, linear between samples), so
only the force law's internal states are integrated, by RK4; the law interface is the kernel's."""

from __future__ import annotations

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray


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
