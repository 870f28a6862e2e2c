"""The Newmark-beta time loop, average acceleration (gamma = 1/2, beta = 1/4) for q and the trapezoidal rule for z,
second order. The implicit nonlinear step is solved by fixed-point iteration on the linear Newmark operator
(K + 2C/dt + 4M/dt²): it contracts when the force law's tangent stiffness and damping are small against 4M/dt² and
2C/dt (true for suspension struts at millisecond steps). Steps that did not converge are counted
(`KernelResult.unconverged`); stiff force laws will need a Newton step there. The law is passed as an argument."""

from __future__ import annotations

import numba
import numpy as np

from .rates import strut_motion, system_rates

NEWMARK_TOL = 1e-13  # fixed-point tolerance, relative to the size of the step's q and z


NEWMARK_MAX_ITER = 50


@numba.njit(cache=False)  # takes a force law as argument: not cacheable (numba#9237)
def _newmark_step(q, v, z, a, f, zd, y0, y1, dt, MT, CT, Br, Dr, Er, KhT, force, par, W):  # pragma: no cover
    """One average-acceleration Newmark step (trapezoidal rule for z) in place; returns 1 if the
    fixed-point iteration did not converge. a, f, zd: rates at the old state on entry, new on exit.
    MT, CT, KhT: M, C and Khat^-1 transposed (rows innermost); Br, Dr, Er: B, D, E as nonzeros."""
    nq, ns, nz, nu = q.shape[0], f.shape[0], z.shape[0], y0.shape[0]
    Bc, Bv, Bn = Br
    Dc, Dv, Dn = Dr
    base, qn, vn, an, rhs = W[0, :nq], W[1, :nq], W[2, :nq], W[3, :nq], W[4, :nq]
    d, dd, fg, fn = W[5, :ns], W[6, :ns], W[7, :ns], W[8, :ns]
    zg, zdn, yd = W[9, :nz], W[10, :nz], W[11, :nu]
    a0, a1, a2 = 4.0 / (dt * dt), 2.0 / dt, 4.0 / dt  # beta = 1/4, gamma = 1/2: a3 = a4 = 1, a5 = 0
    for c in range(nu):
        yd[c] = (y1[c] - y0[c]) / dt
    for i in range(nq):  # the part of the right-hand side that the iteration does not change
        r = 0.0
        for k in range(Bn[i]):
            r += Bv[i, k] * y1[Bc[i, k]]
        base[i] = r
    for j in range(nq):
        mj, cj = a0 * q[j] + a2 * v[j] + a[j], a1 * q[j] + v[j]
        for i in range(nq):
            base[i] += MT[j, i] * mj + CT[j, i] * cj
    for i in range(ns):
        fg[i] = f[i]
    for i in range(nz):
        zg[i] = z[i] + dt * zd[i]
    failed = 1
    for _ in range(NEWMARK_MAX_ITER):
        for i in range(nq):
            rhs[i] = base[i]
        for s_ in range(ns):
            fs = fg[s_]
            for k in range(Dn[s_]):
                rhs[Dc[s_, k]] -= Dv[s_, k] * fs
        for i in range(nq):
            qn[i] = 0.0
        for j in range(nq):
            rj = rhs[j]
            for i in range(nq):
                qn[i] += KhT[j, i] * rj
        for i in range(nq):
            an[i] = a0 * (qn[i] - q[i]) - a2 * v[i] - a[i]
            vn[i] = v[i] + 0.5 * dt * (a[i] + an[i])
        strut_motion(qn, vn, y1, yd, Dr, Er, d, dd)
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


@numba.njit(cache=False, nogil=True)  # takes a force law as argument: not cacheable (numba#9237)
def newmark_loop(
    Mr, CT, KT, Br, Dr, Er, MT, KhT, u, dt, force, params, q0, z0, out_q, out_v, out_a, out_f, out_z, unconverged
):  # pragma: no cover - compiled
    """The Newmark time loop: every system p of the batch, every step k (each iterating to its own convergence).

    Mr, Br, Dr, Er: M^-1, B (P, n_q, n_u), D (P, n_s, n_q), E (P, n_s, n_u) as (columns (R, w), values
    (P, R, w), counts (R,)) of their nonzeros (``_nonzero_rows``); CT, KT, MT, KhT (P, n_q, n_q): C, K, M and
    the Newmark operator's inverse, transposed. params (P, n_par), q0 (P, n_q), z0 (P, n_z), road u (1 or P,
    n, n_u) [m], dt [s]; outputs (P, n, .) get q, qd, qdd, the strut forces [N] and the internal states at
    every sample. Where the road drives struts (E != 0) the rates at a sample are the left limit (end of the
    step before); each step starts from the right limit, re-evaluated when the road's slope changes.
    """
    P, n = out_q.shape[0], u.shape[1]
    nq, ns, nz, nu = q0.shape[1], out_f.shape[2], z0.shape[1], u.shape[2]
    width = max(nq, ns, nz, nu, 1)
    W = np.zeros((20, width))
    q, v, a = np.empty(nq), np.empty(nq), np.empty(nq)
    z, zd, f = np.empty(nz), np.empty(nz), np.empty(ns)
    yd = np.empty(nu)
    rhs, d, dd = np.empty(nq), np.empty(ns), np.empty(ns)
    road_drives_struts = False
    for i in range(ns):
        if Er[2][i] > 0:
            road_drives_struts = True
    for p in range(P):
        r = 0 if u.shape[0] == 1 else p
        par = params[p]
        Bp, Mp = (Br[0], Br[1][p], Br[2]), (Mr[0], Mr[1][p], Mr[2])
        Dp, Ep = (Dr[0], Dr[1][p], Dr[2]), (Er[0], Er[1][p], Er[2])
        for i in range(nq):
            q[i] = q0[p, i]
            v[i] = 0.0
        for i in range(nz):
            z[i] = z0[p, i]
        for c in range(nu):
            yd[c] = (u[r, 1, c] - u[r, 0, c]) / dt
        system_rates(q, v, z, u[r, 0], yd, Mp, CT[p], KT[p], Bp, Dp, Ep, force, par, d, dd, f, zd, rhs, a)
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
                    system_rates(
                        q, v, z, u[r, k - 1], yd, Mp, CT[p], KT[p], Bp, Dp, Ep, force, par, d, dd, f, zd, rhs, a
                    )
            if k > 0:
                unconverged[p] += _newmark_step(
                    q, v, z, a, f, zd, u[r, k - 1], u[r, k], dt, MT[p], CT[p], Bp, Dp, Ep, KhT[p], force, par, W
                )
            for i in range(nq):
                out_q[p, k, i] = q[i]
                out_v[p, k, i] = v[i]
                out_a[p, k, i] = a[i]
            for i in range(ns):
                out_f[p, k, i] = f[i]
            for i in range(nz):
                out_z[p, k, i] = z[i]
