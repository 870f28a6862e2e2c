"""Compiled fixed-step integrators (RK4, Newmark-beta) for linear structures with pluggable nonlinear forces.

The model, batched over P parameter sets (index p), with n_q coordinates q, n_s struts and n_z internal
states z of the force laws:

    M qdd + C qd + K q + D' f = B y(t),     d = D q + E y,   dd = D qd + E yd,
    f, zd = force(d, dd, z, params)

M, C, K, B the linear part; D maps coordinates to strut deflections (``fullcar_struts`` gives the full
car's [G, -I]); E lets the road drive a strut directly (a damper on a test bench has n_q = 0 and d = y).
The road y is sampled every dt and linear between samples (first-order hold), the assumption of the
``exact`` linear path, so the linear car through this kernel differs from ``exact`` by the scheme
error only.

A force law is a numba-jitted function ``force(d (n_s,), dd (n_s,), z (n_z,), params (n_par,),
f_out (n_s,), zd_out (n_z,)) -> None`` writing the strut forces [N] (positive resisting positive
deflection, like k d) and the rates of its internal states. Bouc-Wen, friction, asymmetric damping,
backlash and lag all fit this shape; each law's params row is one candidate's parameters.

The time loop lives in one place (``_integrate``); the schemes are single-step functions:

* RK4: classical fourth order, explicit (stable for |lam dt| up to about 2.8).
* Newmark-beta, average acceleration (gamma = 1/2, beta = 1/4) for q and the trapezoidal rule for z,
  second order. The implicit nonlinear step is solved by fixed-point iteration on the linear
  Newmark operator (K + 2C/dt + 4M/dt²): it contracts when the force law's tangent stiffness and
  damping are small against 4M/dt² and 2C/dt (true for suspension struts at millisecond steps).
  Steps that did not converge are counted in ``KernelResult.unconverged``; stiff force laws will
  need a Newton step there.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..models.fullcar import N_CORNERS, N_DOF, FullCarMatrices
from .linear import Response

RK4, NEWMARK = 0, 1
METHODS = {"rk4": RK4, "newmark": NEWMARK}
NEWMARK_TOL = 1e-13  # fixed-point tolerance, relative to the size of the step's q and z
NEWMARK_MAX_ITER = 50


@numba.njit(cache=True)
def no_force(d, dd, z, params, f_out, zd_out):  # pragma: no cover - compiled
    """The linear structure itself: no strut force, no internal state."""
    for i in range(f_out.shape[0]):
        f_out[i] = 0.0


@numba.njit(cache=True)
def cubic_spring(d, dd, z, params, f_out, zd_out):  # pragma: no cover - compiled
    """f_i = k3 d_i^3 [N] in every strut, params = [k3 (N/m³)]: a hardening spring beside the linear one."""
    k3 = params[0]
    for i in range(f_out.shape[0]):
        f_out[i] = k3 * d[i] * d[i] * d[i]


@numba.njit(cache=True)
def _strut_motion(q, v, y, yd, D, E, d, dd):  # pragma: no cover - compiled
    """Strut deflections and rates: d = D q + E y, dd = D v + E yd (written into d, dd)."""
    for i in range(d.shape[0]):
        s, sd = 0.0, 0.0
        for j in range(q.shape[0]):
            s += D[i, j] * q[j]
            sd += D[i, j] * v[j]
        for c in range(y.shape[0]):
            s += E[i, c] * y[c]
            sd += E[i, c] * yd[c]
        d[i] = s
        dd[i] = sd


@numba.njit(cache=False)  # takes a force law as argument: not cacheable (numba#9237)
def _rates(q, v, z, y, yd, Minv, C, K, B, D, E, force, par, d, dd, f, zd, rhs, a):  # pragma: no cover
    """Acceleration a and internal rates zd at state (q, v, z) and road (y, yd); f gets the strut forces."""
    nq, ns, nu = q.shape[0], d.shape[0], y.shape[0]
    _strut_motion(q, v, y, yd, D, E, d, dd)
    force(d, dd, z, par, f, zd)
    for i in range(nq):
        r = 0.0
        for c in range(nu):
            r += B[i, c] * y[c]
        for j in range(nq):
            r -= C[i, j] * v[j] + K[i, j] * q[j]
        for s_ in range(ns):
            r -= D[s_, i] * f[s_]
        rhs[i] = r
    for i in range(nq):
        acc = 0.0
        for j in range(nq):
            acc += Minv[i, j] * rhs[j]
        a[i] = acc


@numba.njit(cache=False)  # takes a force law as argument: not cacheable (numba#9237)
def _rk4_step(q, v, z, a, f, zd, y0, y1, dt, Minv, C, K, B, D, E, force, par, W):  # pragma: no cover - compiled
    """One RK4 step of (q, v, z) in place. On entry a, f, zd hold the rates at the old state (stage 1);
    on exit the rates at the new state, ready for the output and the next step. W is scratch."""
    nq, ns, nz, nu = q.shape[0], f.shape[0], z.shape[0], y0.shape[0]
    d, dd, rhs, qs, vs, zs, ym, yd = (
        W[0, :ns],
        W[1, :ns],
        W[2, :nq],
        W[3, :nq],
        W[4, :nq],
        W[5, :nz],
        W[6, :nu],
        W[7, :nu],
    )
    kq, kv, kz = W[8:12, :nq], W[12:16, :nq], W[16:20, :nz]  # stage slopes
    for c in range(nu):
        yd[c] = (y1[c] - y0[c]) / dt
        ym[c] = 0.5 * (y0[c] + y1[c])
    for i in range(nq):
        kq[0, i] = v[i]
        kv[0, i] = a[i]
    for i in range(nz):
        kz[0, i] = zd[i]
    for stage in range(1, 4):
        h = dt if stage == 3 else 0.5 * dt
        for i in range(nq):
            qs[i] = q[i] + h * kq[stage - 1, i]
            vs[i] = v[i] + h * kv[stage - 1, i]
        for i in range(nz):
            zs[i] = z[i] + h * kz[stage - 1, i]
        y = y1 if stage == 3 else ym
        _rates(qs, vs, zs, y, yd, Minv, C, K, B, D, E, force, par, d, dd, f, zd, rhs, a)
        for i in range(nq):
            kq[stage, i] = vs[i]
            kv[stage, i] = a[i]
        for i in range(nz):
            kz[stage, i] = zd[i]
    for i in range(nq):
        q[i] += dt / 6.0 * (kq[0, i] + 2.0 * kq[1, i] + 2.0 * kq[2, i] + kq[3, i])
        v[i] += dt / 6.0 * (kv[0, i] + 2.0 * kv[1, i] + 2.0 * kv[2, i] + kv[3, i])
    for i in range(nz):
        z[i] += dt / 6.0 * (kz[0, i] + 2.0 * kz[1, i] + 2.0 * kz[2, i] + kz[3, i])
    _rates(q, v, z, y1, yd, Minv, C, K, B, D, E, force, par, d, dd, f, zd, rhs, a)


@numba.njit(cache=False)  # takes a force law as argument: not cacheable (numba#9237)
def _newmark_step(q, v, z, a, f, zd, y0, y1, dt, M, C, K, B, D, E, Khat_inv, force, par, W):  # pragma: no cover
    """One average-acceleration Newmark step (trapezoidal rule for z) in place; returns 1 if the
    fixed-point iteration did not converge. a, f, zd: rates at the old state on entry, new on exit."""
    nq, ns, nz, nu = q.shape[0], f.shape[0], z.shape[0], y0.shape[0]
    base, qn, vn, an, rhs = W[0, :nq], W[1, :nq], W[2, :nq], W[3, :nq], W[4, :nq]
    d, dd, fg, fn = W[5, :ns], W[6, :ns], W[7, :ns], W[8, :ns]
    zg, zdn, yd = W[9, :nz], W[10, :nz], W[11, :nu]
    a0, a1, a2 = 4.0 / (dt * dt), 2.0 / dt, 4.0 / dt  # beta = 1/4, gamma = 1/2: a3 = a4 = 1, a5 = 0
    for c in range(nu):
        yd[c] = (y1[c] - y0[c]) / dt
    for i in range(nq):  # the part of the right-hand side that the iteration does not change
        r = 0.0
        for c in range(nu):
            r += B[i, c] * y1[c]
        for j in range(nq):
            r += M[i, j] * (a0 * q[j] + a2 * v[j] + a[j]) + C[i, j] * (a1 * q[j] + v[j])
        base[i] = r
    for i in range(ns):
        fg[i] = f[i]
    for i in range(nz):
        zg[i] = z[i] + dt * zd[i]
    failed = 1
    for _ in range(NEWMARK_MAX_ITER):
        for i in range(nq):
            r = base[i]
            for s_ in range(ns):
                r -= D[s_, i] * fg[s_]
            rhs[i] = r
        for i in range(nq):
            acc = 0.0
            for j in range(nq):
                acc += Khat_inv[i, j] * rhs[j]
            qn[i] = acc
        for i in range(nq):
            an[i] = a0 * (qn[i] - q[i]) - a2 * v[i] - a[i]
            vn[i] = v[i] + 0.5 * dt * (a[i] + an[i])
        _strut_motion(qn, vn, y1, yd, D, E, d, dd)
        force(d, dd, zg, par, fn, zdn)
        err_f, size_f, err_z, size_z = 0.0, 0.0, 0.0, 0.0
        for i in range(ns):
            err_f = max(err_f, abs(fn[i] - fg[i]))
            size_f = max(size_f, abs(fn[i]))
            fg[i] = fn[i]
        for i in range(nz):
            znew = z[i] + 0.5 * dt * (zd[i] + zdn[i])
            err_z = max(err_z, abs(znew - zg[i]))
            size_z = max(size_z, abs(znew))
            zg[i] = znew
        if err_f <= NEWMARK_TOL * size_f and err_z <= NEWMARK_TOL * size_z:
            failed = 0
            break
    for i in range(nq):
        q[i] = qn[i]
        v[i] = vn[i]
        a[i] = an[i]
    for i in range(ns):
        f[i] = fn[i]
    for i in range(nz):
        z[i] = zg[i]
        zd[i] = zdn[i]
    return failed


@numba.njit(cache=False)  # takes a force law as argument: not cacheable (numba#9237)
def _integrate(
    method,
    M,
    Minv,
    C,
    K,
    B,
    D,
    E,
    Khat_inv,
    u,
    dt,
    force,
    params,
    q0,
    z0,
    out_q,
    out_v,
    out_a,
    out_f,
    out_z,
    unconverged,
):  # pragma: no cover - compiled
    """The one time loop: every car p of the batch, every step k, by RK4 (method 0) or Newmark (1).

    Matrices (P, ., .), params (P, n_par), q0 (P, n_q), z0 (P, n_z), road u (1 or P, n, n_u); outputs
    (P, n, .) get q, qd, qdd, the strut forces and the internal states at every sample. Where the road drives
    struts (E != 0) the rates at a sample are the left limit (end of the step before); each step starts
    from the right limit, re-evaluated when the road's slope changes.
    """
    P, n = out_q.shape[0], u.shape[1]
    nq, ns, nz, nu = q0.shape[1], D.shape[1], z0.shape[1], u.shape[2]
    width = max(nq, ns, nz, nu, 1)
    W = np.zeros((20, width))
    q, v, a = np.empty(nq), np.empty(nq), np.empty(nq)
    z, zd, f = np.empty(nz), np.empty(nz), np.empty(ns)
    yd = np.empty(nu)
    rhs, d, dd = np.empty(nq), np.empty(ns), np.empty(ns)
    for p in range(P):
        r = 0 if u.shape[0] == 1 else p
        par = params[p]
        for i in range(nq):
            q[i] = q0[p, i]
            v[i] = 0.0
        for i in range(nz):
            z[i] = z0[p, i]
        for c in range(nu):
            yd[c] = (u[r, 1, c] - u[r, 0, c]) / dt
        _rates(q, v, z, u[r, 0], yd, Minv[p], C[p], K[p], B[p], D[p], E[p], force, par, d, dd, f, zd, rhs, a)
        road_drives_struts = False
        for i in range(ns):
            for c in range(nu):
                if E[p, i, c] != 0.0:
                    road_drives_struts = True
        for k in range(n):
            if k > 1 and road_drives_struts:
                # The road's slope jumps at samples and the struts see it (dd = D qd + E yd): the rates that
                # start the step are the right limit, at the new slope (else the schemes drop to order 1).
                changed = False
                for c in range(nu):
                    slope = (u[r, k, c] - u[r, k - 1, c]) / dt
                    if slope != yd[c]:
                        changed = True
                        yd[c] = slope
                if changed:
                    _rates(
                        q,
                        v,
                        z,
                        u[r, k - 1],
                        yd,
                        Minv[p],
                        C[p],
                        K[p],
                        B[p],
                        D[p],
                        E[p],
                        force,
                        par,
                        d,
                        dd,
                        f,
                        zd,
                        rhs,
                        a,
                    )
            if k > 0:
                if method == 0:
                    _rk4_step(
                        q,
                        v,
                        z,
                        a,
                        f,
                        zd,
                        u[r, k - 1],
                        u[r, k],
                        dt,
                        Minv[p],
                        C[p],
                        K[p],
                        B[p],
                        D[p],
                        E[p],
                        force,
                        par,
                        W,
                    )
                else:
                    unconverged[p] += _newmark_step(
                        q,
                        v,
                        z,
                        a,
                        f,
                        zd,
                        u[r, k - 1],
                        u[r, k],
                        dt,
                        M[p],
                        C[p],
                        K[p],
                        B[p],
                        D[p],
                        E[p],
                        Khat_inv[p],
                        force,
                        par,
                        W,
                    )
            for i in range(nq):
                out_q[p, k, i] = q[i]
                out_v[p, k, i] = v[i]
                out_a[p, k, i] = a[i]
            for i in range(ns):
                out_f[p, k, i] = f[i]
            for i in range(nz):
                out_z[p, k, i] = z[i]


@dataclass(frozen=True)
class KernelResult:
    """Trajectories of a batch of P systems at the n road samples."""

    q: NDArray  # (P, n, n_q) coordinates
    qd: NDArray  # (P, n, n_q) velocities
    qdd: NDArray  # (P, n, n_q) accelerations
    force: NDArray  # (P, n, n_s) strut forces [N]
    z: NDArray  # (P, n, n_z) internal states of the force law
    unconverged: NDArray  # (P,) Newmark steps whose fixed-point iteration did not converge (0 for RK4)


def _batched(X: ArrayLike, P: int, ndim: int = 2) -> NDArray:
    """A fresh writeable C-contiguous (P, ...) copy: one array type, so numba compiles one specialisation."""
    X = np.asarray(X, dtype=float)
    return np.array(np.broadcast_to(X, (P,) + X.shape[-ndim:]), dtype=float, order="C")


def integrate(
    method: Literal["rk4", "newmark"],
    M: ArrayLike,
    C: ArrayLike,
    K: ArrayLike,
    B: ArrayLike,
    road: ArrayLike,
    dt: float,
    force=no_force,
    params: ArrayLike | None = None,
    n_z: int = 0,
    D: ArrayLike | None = None,
    E: ArrayLike | None = None,
    q0: ArrayLike | None = None,
    z0: ArrayLike | None = None,
) -> KernelResult:
    """Integrate M qdd + C qd + K q + D' f(d, dd, z) = B y for a batch of systems at fixed step dt [s].

    Matrices are (P, ., .) or shared (., .); road (n, n_u) shared or (P, n, n_u), linear between samples;
    params (P, n_par) rows of the force law (shared if 1-D); D (n_s, n_q) and E (n_s, n_u) default to no
    struts. q0 defaults to the linear static equilibrium K q0 = B y0, z0 to zero; velocities start at zero.
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}: choose from {sorted(METHODS)}")
    road = np.asarray(road, dtype=float)
    shapes = [np.shape(X)[:-2] for X in (M, C, K, B)] + [road.shape[:-2]]
    P = int(np.prod(np.broadcast_shapes(*shapes), dtype=int))
    n, nu = road.shape[-2:]
    M, C, K, B = (_batched(X, P) for X in (M, C, K, B))
    nq = M.shape[-1]
    D = _batched(np.zeros((0, nq)) if D is None else D, P)
    ns = D.shape[-2]
    E = _batched(np.zeros((ns, nu)) if E is None else E, P)
    u = np.array(road.reshape(-1, n, nu), dtype=float, order="C")
    if params is None:
        params = np.zeros((P, 0))
    params = _batched(np.atleast_1d(params), P, ndim=1)
    q0 = np.linalg.solve(K, B @ np.broadcast_to(u[:, 0], (P, nu))[..., None])[..., 0] if q0 is None else q0
    q0 = _batched(q0, P, ndim=1)
    z0 = _batched(np.zeros(n_z) if z0 is None else z0, P, ndim=1)
    Minv = np.linalg.inv(M)
    Khat_inv = np.linalg.inv(K + (2.0 / dt) * C + (4.0 / dt**2) * M)
    out_q, out_v, out_a = (np.empty((P, n, nq)) for _ in range(3))
    out_f, out_z = np.empty((P, n, ns)), np.empty((P, n, n_z))
    unconverged = np.zeros(P, dtype=np.int64)
    _integrate(
        METHODS[method],
        M,
        Minv,
        C,
        K,
        B,
        D,
        E,
        Khat_inv,
        u,
        float(dt),
        force,
        params,
        q0,
        z0,
        out_q,
        out_v,
        out_a,
        out_f,
        out_z,
        unconverged,
    )
    return KernelResult(q=out_q, qd=out_v, qdd=out_a, force=out_f, z=out_z, unconverged=unconverged)


def fullcar_struts(mats: FullCarMatrices) -> NDArray:
    """D (..., 4, 7) = [G, -I]: suspension deflection of each corner (body point minus wheel) [m]."""
    D = np.zeros(mats.batch_shape + (N_CORNERS, N_DOF))
    D[..., :, :3] = mats.G
    D[..., :, 3:] = -np.eye(N_CORNERS)
    return D


def simulate_fullcar(
    mats: FullCarMatrices,
    road: ArrayLike,
    dt: float,
    method: Literal["rk4", "newmark"],
    force=no_force,
    params: ArrayLike | None = None,
    n_z: int = 0,
) -> tuple[Response, KernelResult]:
    """The full car with a strut force law added at each corner (on top of its linear springs and dampers).

    Returns the Response (batch flattened to (P, n, .), or (n, .) for one car) and the raw kernel result.
    """
    P = int(np.prod(mats.batch_shape, dtype=int))
    res = integrate(
        method,
        mats.M.reshape(P, N_DOF, N_DOF),
        mats.C.reshape(P, N_DOF, N_DOF),
        mats.K.reshape(P, N_DOF, N_DOF),
        mats.B.reshape(P, N_DOF, N_CORNERS),
        road,
        dt,
        force,
        params,
        n_z,
        D=fullcar_struts(mats).reshape(P, N_CORNERS, N_DOF),
    )
    G = np.broadcast_to(mats.G, mats.batch_shape + (N_CORNERS, 3)).reshape(P, N_CORNERS, 3)
    Gt = np.swapaxes(G, -1, -2)
    q, qd, qdd = res.q, res.qd, res.qdd
    disp, acc = q[..., :3] @ Gt, qdd[..., :3] @ Gt
    if mats.batch_shape == ():
        q, qd, qdd, disp, acc = q[0], qd[0], qdd[0], disp[0], acc[0]
    t = np.arange(q.shape[-2]) * dt
    return Response(t=t, q=q, qd=qd, qdd=qdd, disp=disp, acc=acc), res


# ------------------------------------------------------------------------------------------ test bench


@numba.njit(cache=False)  # takes a force law as argument: not cacheable (numba#9237)
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
