"""Compiled fixed-step integrators (RK4, Newmark-beta) for linear structures with pluggable nonlinear forces.

The model, batched over P parameter sets (index p), with n_q coordinates q, n_s struts and n_z internal
states z of the force laws:

    M qdd + C qd + K q + D' f = B y(t),     d = D q + E y,   dd = D qd + E yd,
    f, zd = force(d, dd, z, params)

M, C, K, B the linear part; D maps coordinates to strut deflections (``sim.nonlinear.fullcar_struts`` gives
the full car's [G, -I]); E lets the road drive a strut directly (a damper on a test bench has n_q = 0 and d = y).
The road y is sampled every dt and linear between samples (first-order hold), the assumption of the
``exact`` linear path, so the linear car through this kernel differs from ``exact`` by the scheme
error only.

A force law is a numba-jitted function ``force(d (n_s,), dd (n_s,), z (n_z,), params (n_par,),
f_out (n_s,), zd_out (n_z,)) -> None`` writing the strut forces [N] (positive resisting positive
deflection, like k d) and the rates of its internal states. Bouc-Wen, friction, asymmetric damping,
backlash and lag all fit this shape; each law's params row is one candidate's parameters.

Two time loops, one per scheme:

* RK4: classical fourth order, explicit (stable for |lam dt| up to about 2.8). ``_rk4_loop`` compiles the
  loop per force law with the law inlined (four evaluations per step): the path of the nonlinear car.
* Newmark-beta, average acceleration (gamma = 1/2, beta = 1/4) for q and the trapezoidal rule for z,
  second order. The implicit nonlinear step is solved by fixed-point iteration on the linear
  Newmark operator (K + 2C/dt + 4M/dt²): it contracts when the force law's tangent stiffness and
  damping are small against 4M/dt² and 2C/dt (true for suspension struts at millisecond steps).
  Steps that did not converge are counted in ``KernelResult.unconverged``; stiff force laws will
  need a Newton step there. ``_integrate_newmark``, the law passed as an argument.

Both evaluate the same rates (``_strut_motion``, the law, ``_linear_rates``) with the same arithmetic as
dense loops over M^-1, B, C, K, D and E, in the same order, so results do not depend on the speed-ups:
M^-1, B, D and E enter as their nonzeros (the car's M^-1 is diagonal, B has one entry per wheel, a strut
touches four coordinates), C and K transposed so that the rows' sums advance together. (Bit for bit with
finite numbers; a diverging candidate still turns NaN everywhere, through the dense C and K sums.)
"""

from __future__ import annotations

import functools
import hashlib
import inspect
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numba
import numpy as np
from numba.core.caching import FunctionCache
from numpy.typing import ArrayLike, NDArray

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


@numba.njit(cache=True, inline="always")
def _strut_motion(q, v, y, yd, Dr, Er, d, dd):  # pragma: no cover - compiled
    """Strut deflections and rates of one system: d = D q + E y, dd = D v + E yd (written into d, dd), D and
    E as (columns, values, counts) of their nonzeros (``_nonzero_rows``, the values of this system).

    Each sum runs over the columns in order, as the dense loop would, without its exact zeros (they add
    nothing): the same numbers."""
    Dc, Dv, Dn = Dr
    Ec, Ev, En = Er
    for s_ in range(d.shape[0]):
        s, sd = 0.0, 0.0
        for k in range(Dn[s_]):
            j, w = Dc[s_, k], Dv[s_, k]
            s += w * q[j]
            sd += w * v[j]
        for k in range(En[s_]):
            c, w = Ec[s_, k], Ev[s_, k]
            s += w * y[c]
            sd += w * yd[c]
        d[s_] = s
        dd[s_] = sd


@numba.njit(cache=True, inline="always")
def _linear_rates(q, v, y, f, Mr, CT, KT, Br, Dr, rhs, a):  # pragma: no cover - compiled
    """Acceleration a = M^-1 rhs [m/s², rad/s²] of one system, rhs = B y - C v - K q - D' f its generalised
    force [N, N m] at state q, v, road y and strut forces f [N].

    M^-1, B and D come as nonzeros (``_nonzero_rows``), C and K transposed (CT[j] = column j), so the loop
    over the rows i is innermost: n_q independent sums advancing together instead of one dependent chain
    per row. Each row still sums in the dense loop's order (B's columns, then the coordinates j, then the
    struts): the same numbers."""
    nq = q.shape[0]
    Bc, Bv, Bn = Br
    Dc, Dv, Dn = Dr
    Mc, Mv, Mn = Mr
    for i in range(nq):
        r = 0.0
        for k in range(Bn[i]):
            r += Bv[i, k] * y[Bc[i, k]]
        rhs[i] = r
    for j in range(nq):
        vj, qj = v[j], q[j]
        for i in range(nq):
            rhs[i] -= CT[j, i] * vj + KT[j, i] * qj
    for s_ in range(f.shape[0]):
        fs = f[s_]
        for k in range(Dn[s_]):
            rhs[Dc[s_, k]] -= Dv[s_, k] * fs
    for i in range(nq):
        acc = 0.0
        for k in range(Mn[i]):
            acc += Mv[i, k] * rhs[Mc[i, k]]
        a[i] = acc


@numba.njit(cache=False)  # takes a force law as argument: not cacheable (numba#9237)
def _rates(q, v, z, y, yd, Mr, CT, KT, Br, Dr, Er, force, par, d, dd, f, zd, rhs, a):  # pragma: no cover
    """Acceleration a and internal rates zd of one system at state (q, v, z) and road (y, yd); f gets the
    strut forces, d and dd the strut motion."""
    _strut_motion(q, v, y, yd, Dr, Er, d, dd)
    force(d, dd, z, par, f, zd)
    _linear_rates(q, v, y, f, Mr, CT, KT, Br, Dr, rhs, a)


INLINE_OPTIONS = {"nopython", "error_model", "boundscheck", "cache"}  # a law compiled with only these is inlined


def _inlined(force):
    """The force law recompiled from its Python source with ``inline="always"`` (numba inlines it where it is
    called), and the error model to compile its caller with (which then applies to the law's code too).

    A call to a compiled law costs about 25 ns on top of its arithmetic (its six arrays are passed as some
    forty words on the stack), as much as the Bouc-Wen struts themselves, four times per RK4 step. A law
    compiled with other options (fastmath, ...) would not keep them inlined: it is returned as it is."""
    options = dict(getattr(force, "targetoptions", {}))
    error_model = options.get("error_model", "python")
    py_func = getattr(force, "py_func", None)
    if py_func is None or not set(options) <= INLINE_OPTIONS or options.get("boundscheck"):
        return force, error_model
    return numba.njit(inline="always", error_model=error_model)(py_func), error_model


class _KeyedCache(FunctionCache):
    """numba's on-disk function cache keyed by our own digest instead of the closure's pickled cells (which
    hold freshly made dispatchers, so numba's own key differs in every process and the cache never hits)."""

    def __init__(self, py_func, key: str):
        super().__init__(py_func)
        self._key = key

    def _index_key(self, sig, codegen):
        return (sig, codegen.magic_tuple(), (hashlib.sha256(self._py_func.__code__.co_code).hexdigest(), self._key))


def _cache_key(force, error_model: str, *sizes: int) -> str | None:
    """A digest of what the compiled loop for `force` depends on: this file, the source file that defines the
    law (its helpers too), what a composed law says it is made of (its `cache_salt`: the sources of the pieces it
    was composed from), the error model and the sizes; None when the law's source cannot be read (then the loop is
    compiled afresh in each process)."""
    try:
        law_file = inspect.getsourcefile(force.py_func)
        if not law_file:
            return None
        parts = [Path(__file__).read_bytes(), Path(law_file).read_bytes(), force.py_func.__qualname__.encode()]
    except (AttributeError, OSError, TypeError):
        return None
    parts.append(str(getattr(force, "cache_salt", "")).encode())
    parts.append(repr((error_model, sizes, numba.__version__)).encode())
    return hashlib.sha256(b"\0".join(parts)).hexdigest()


@functools.cache
def _rk4_loop(force, nq: int, ns: int, nu: int):
    """The RK4 time loop compiled for one force law, n_q coordinates, n_s struts and n_u road channels.

    The law is inlined at its four evaluations per step (``_inlined``) and the sizes are compile-time
    constants, so the small loops of the step unroll (twice as fast as with the sizes read from the arrays).
    Returns run(Mr, CT, KT, Br, Dr, Er, u, dt, params, q0, z0, out_q, out_v, out_a, out_f, out_z), arguments
    as ``_integrate_newmark``'s; compiled on first use, once per law and sizes, and cached on disk by numba
    (loaded in about 0.2 s instead of compiled in about six). (The law is part of the code: a law passed as
    an argument, as Newmark's loop takes it, cannot be inlined.)"""
    law, error_model = _inlined(force)
    key = _cache_key(force, error_model, nq, ns, nu)

    @numba.njit(inline="always", error_model=error_model)
    def rates(q, v, z, y, yd, Mr, CT, KT, Br, Dr, Er, par, d, dd, f, zd, rhs, a):  # pragma: no cover
        """``_rates`` with this law."""
        _strut_motion(q, v, y, yd, Dr, Er, d, dd)
        law(d, dd, z, par, f, zd)
        _linear_rates(q, v, y, f, Mr, CT, KT, Br, Dr, rhs, a)

    @numba.njit(nogil=True, error_model=error_model)  # nogil: candidate fits run in parallel threads
    def run(Mr, CT, KT, Br, Dr, Er, u, dt, params, q0, z0, out_q, out_v, out_a, out_f, out_z):  # pragma: no cover
        """Every system p of the batch, every step k, by classical RK4; see ``_integrate_newmark``.

        The rates are evaluated at two places, the stages and the current state (fewer copies of the inlined
        law: compile time), the stage-1 slopes of a step being the rates at the end of the step before."""
        P, n = out_q.shape[0], u.shape[1]
        nz = z0.shape[1]
        q, v, qs, vs, a_s, rhs = np.empty(nq), np.empty(nq), np.empty(nq), np.empty(nq), np.empty(nq), np.empty(nq)
        z, zs, zd_s = np.empty(nz), np.empty(nz), np.empty(nz)
        f, d, dd = np.empty(ns), np.empty(ns), np.empty(ns)
        y1, ym, yd, slopes = np.empty(nu), np.empty(nu), np.empty(nu), np.empty(nu)
        # Stage slopes: kq[s] the stage velocities (kq[0] would be v itself), kv[s] the accelerations, kz[s]
        # the internal rates; kv[0], kz[0] (a, zd) hold the rates at the current state (the output, and stage
        # 1). The stages evaluate into the 1-D qs, vs, zs, a_s, zd_s: no array views made in the time loop.
        kq, kv, kz = np.empty((4, nq)), np.empty((4, nq)), np.empty((4, nz))
        a, zd = kv[0], kz[0]
        road_drives_struts = False
        for i in range(ns):
            if Er[2][i] > 0:
                road_drives_struts = True
        for p in range(P):
            r = 0 if u.shape[0] == 1 else p
            par = params[p]
            Mp, Bp = (Mr[0], Mr[1][p], Mr[2]), (Br[0], Br[1][p], Br[2])
            Dp, Ep = (Dr[0], Dr[1][p], Dr[2]), (Er[0], Er[1][p], Er[2])
            CTp, KTp = CT[p], KT[p]
            for i in range(nq):
                q[i] = q0[p, i]
                v[i] = 0.0
            for i in range(nz):
                z[i] = z0[p, i]
            for c in range(nu):
                slopes[c] = (u[r, 1, c] - u[r, 0, c]) / dt
                yd[c] = slopes[c]  # the slope at the first sample (later: of the step just taken)
            for k in range(n):
                for c in range(nu):
                    y1[c] = u[r, k, c]
                if k > 0:
                    for c in range(nu):
                        y0c = u[r, k - 1, c]
                        yd[c] = (y1[c] - y0c) / dt
                        ym[c] = 0.5 * (y0c + y1[c])
                    for stage in range(1, 4):
                        h = dt if stage == 3 else 0.5 * dt
                        for i in range(nq):
                            qs[i] = q[i] + h * (v[i] if stage == 1 else kq[stage - 1, i])
                            vs[i] = kq[stage, i] = v[i] + h * kv[stage - 1, i]
                        for i in range(nz):
                            zs[i] = z[i] + h * kz[stage - 1, i]
                        y = y1 if stage == 3 else ym
                        rates(qs, vs, zs, y, yd, Mp, CTp, KTp, Bp, Dp, Ep, par, d, dd, f, zd_s, rhs, a_s)
                        for i in range(nq):
                            kv[stage, i] = a_s[i]
                        for i in range(nz):
                            kz[stage, i] = zd_s[i]
                    for i in range(nq):
                        q[i] += dt / 6.0 * (v[i] + 2.0 * kq[1, i] + 2.0 * kq[2, i] + kq[3, i])
                        v[i] += dt / 6.0 * (kv[0, i] + 2.0 * kv[1, i] + 2.0 * kv[2, i] + kv[3, i])
                    for i in range(nz):
                        z[i] += dt / 6.0 * (kz[0, i] + 2.0 * kz[1, i] + 2.0 * kz[2, i] + kz[3, i])
                for again in range(2):  # the rates at sample k: the output, then maybe the right limit
                    if again:
                        # The road's slope jumps at samples and the struts see it (dd = D qd + E yd): the rates
                        # that start the next step are the right limit, at its slope (else the schemes drop to
                        # order 1). The output keeps the left limit (the end of this step).
                        changed = False
                        if road_drives_struts and 0 < k < n - 1:
                            for c in range(nu):
                                slope = (u[r, k + 1, c] - y1[c]) / dt
                                if slope != slopes[c]:
                                    changed = True
                                    slopes[c] = slope
                        if not changed:
                            break
                        for c in range(nu):
                            yd[c] = slopes[c]
                    rates(q, v, z, y1, yd, Mp, CTp, KTp, Bp, Dp, Ep, par, d, dd, f, zd, rhs, a)
                    if not again:
                        for i in range(nq):
                            out_q[p, k, i] = q[i]
                            out_v[p, k, i] = v[i]
                            out_a[p, k, i] = kv[0, i]
                        for i in range(ns):
                            out_f[p, k, i] = f[i]
                        for i in range(nz):
                            out_z[p, k, i] = z[i]

    if key is not None:
        run._cache = _KeyedCache(run.py_func, key)  # numba's on-disk cache, under our own key
    return run


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
        _strut_motion(qn, vn, y1, yd, Dr, Er, d, dd)
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
def _integrate_newmark(
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
        _rates(q, v, z, u[r, 0], yd, Mp, CT[p], KT[p], Bp, Dp, Ep, force, par, d, dd, f, zd, rhs, a)
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
                    _rates(q, v, z, u[r, k - 1], yd, Mp, CT[p], KT[p], Bp, Dp, Ep, force, par, d, dd, f, zd, rhs, a)
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


def _nonzero_rows(X: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """The nonzero pattern of X (P, R, C), shared by the batch: per row the columns where any system has a
    nonzero, in column order, as columns (R, w) int64, values (P, R, w) and counts (R,) int64; w is the
    largest count (at least 1; slots past a row's count hold column 0, value 0). NaN counts as nonzero.

    The kernel sums only these, in the dense loops' order: the same numbers (an exact zero adds nothing)
    at a fraction of the work for the car's diagonal M^-1, the road's B (one column per wheel) and the
    struts' D = [G, -I] and E."""
    nonzero = np.any(X != 0.0, axis=0)
    counts = nonzero.sum(axis=-1)
    w = max(int(counts.max(initial=0)), 1)
    cols = np.argsort(~nonzero, axis=-1, kind="stable")[:, :w]  # nonzero columns first, in column order
    used = np.arange(w) < counts[:, None]
    cols = np.where(used, cols, 0)
    vals = np.where(used, X[:, np.arange(X.shape[1])[:, None], cols], 0.0)
    return (
        np.ascontiguousarray(cols, dtype=np.int64),
        np.ascontiguousarray(vals, dtype=float),
        np.ascontiguousarray(counts, dtype=np.int64),
    )


_THREADS: int | None = None  # threads one batch is split over (None: the cores this process may use)


def set_threads(n: int | None) -> None:
    """Split each batch over at most n threads (1: none; None: the cores this process may use). Pool workers
    of a campaign set 1: their parallelism is over runs."""
    global _THREADS
    _THREADS = n


def available_cores() -> int:
    """The cores this process may use (its CPU affinity)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def _in_parallel(P: int, rows) -> None:
    """rows(slice) over the batch's P systems, split into contiguous parts over threads (the compiled loops
    release the GIL; each system is integrated alone, so results are the same as in one call). Only from the
    main thread: a caller already running threads (parallel candidate fits) keeps its own split."""
    k = min(_THREADS or available_cores(), P)
    if k <= 1 or threading.current_thread() is not threading.main_thread():
        rows(slice(0, P))
        return
    bounds = np.linspace(0, P, k + 1).astype(int)
    with ThreadPoolExecutor(k) as pool:
        list(pool.map(rows, [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]))


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
    CT, KT = (np.ascontiguousarray(np.swapaxes(X, -1, -2)) for X in (C, K))
    Mr, Br, Dr, Er = (_nonzero_rows(X) for X in (Minv, B, D, E))
    # One buffer for q, qd, qdd: an allocation this large is returned to the allocator whole and reused by the
    # next call, where three separate ones page-fault afresh every call (~5 ms for a batch of 20 cars).
    out_q, out_v, out_a = np.empty((3, P, n, nq))
    out_f, out_z = np.empty((P, n, ns)), np.empty((P, n, n_z))
    unconverged = np.zeros(P, dtype=np.int64)
    if method == "rk4":
        run = _rk4_loop(force, nq, ns, nu)

        def rows(s: slice) -> None:
            def part(X):
                return (X[0], X[1][s], X[2])

            us = u if u.shape[0] == 1 else u[s]
            run(part(Mr), CT[s], KT[s], part(Br), part(Dr), part(Er), us, float(dt), params[s], q0[s], z0[s],
                out_q[s], out_v[s], out_a[s], out_f[s], out_z[s])  # fmt: skip

        _in_parallel(P, rows)
    else:
        Khat_inv = np.linalg.inv(K + (2.0 / dt) * C + (4.0 / dt**2) * M)
        MT, KhT = (np.ascontiguousarray(np.swapaxes(X, -1, -2)) for X in (M, Khat_inv))
        _integrate_newmark(
            Mr,
            CT,
            KT,
            Br,
            Dr,
            Er,
            MT,
            KhT,
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


# ------------------------------------------------------------------------------------------ test bench


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
