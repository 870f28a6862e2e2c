"""The RK4 time loop (classical fourth order, explicit, stable for |lam dt| up to about 2.8), compiled per force law
with the law inlined at its four evaluations per step and the sizes as compile-time constants; the compiled loop is
cached on disk by numba under our own digest (the sources it is made of), so a new process loads it in about 0.2 s
instead of compiling it in about six. The path of the nonlinear car."""

from __future__ import annotations

import functools
import hashlib
import inspect
from pathlib import Path

import numba
import numpy as np
from numpy.typing import NDArray

from ..core.jit import KeyedCache
from . import rates as rates_module
from .rates import linear_rates, strut_motion

INLINE_OPTIONS = {"nopython", "error_model", "boundscheck", "cache", "nogil"}  # a law with only these is inlined


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


def _cache_key(force, error_model: str, *sizes: object, loop_files: tuple[str, ...] = ()) -> str | None:
    """A digest of what the compiled loop for `force` depends on: this file (or the loop's own files,
    `loop_files`), the source file that defines the law (its helpers too), what a composed law says it is made of
    (its `cache_salt`: the sources of the pieces it was composed from), the error model, the law's compile options
    (they decide whether it is inlined), the sizes and the nonzero pattern; None when the law's source cannot be read
    (then the loop is compiled afresh in each process)."""
    try:
        law_file = inspect.getsourcefile(force.py_func)
        if not law_file:
            return None
        files = loop_files or (__file__, rates_module.__file__)  # the loop and its rates
        own = [Path(f).read_bytes() for f in files]
        parts = [*own, Path(law_file).read_bytes(), force.py_func.__qualname__.encode()]
    except (AttributeError, OSError, TypeError):
        return None
    parts.append(str(getattr(force, "cache_salt", "")).encode())
    options = sorted(getattr(force, "targetoptions", {}).items())  # (whether `_inlined` inlines the law)
    parts.append(repr((error_model, sizes, options, numba.__version__)).encode())
    return hashlib.sha256(b"\0".join(parts)).hexdigest()


Pattern = tuple[tuple[tuple[tuple[int, ...], ...], tuple[int, ...]], ...]  # (columns, counts) of M^-1, B, D, E


def nonzero_pattern(*rows: tuple) -> Pattern:
    """The nonzero pattern (columns, counts) of each of the kernel's (columns, values, counts) matrices, as tuples: the
    key a loop is compiled for (``rk4_loop``)."""
    return tuple((tuple(map(tuple, cols.tolist())), tuple(counts.tolist())) for cols, _, counts in rows)


def _constants(cols: tuple, counts: tuple) -> tuple[NDArray, NDArray]:
    """A pattern's columns (R, w) and counts (R,) as the int64 arrays the rates index."""
    n = np.array(counts, dtype=np.int64)
    return (np.array(cols, dtype=np.int64).reshape(n.size, -1) if n.size else np.zeros((0, 1), np.int64)), n


@functools.cache
def rk4_loop(force, nq: int, ns: int, nu: int, pattern: Pattern):
    """The RK4 time loop compiled for one force law, n_q coordinates, n_s struts, n_u road channels and the nonzero
    pattern of M^-1, B, D and E (``nonzero_pattern``; the values stay arguments).

    The law is inlined at its four evaluations per step (``_inlined``) and the sizes are compile-time
    constants, so the small loops of the step unroll (twice as fast as with the sizes read from the arrays); so are
    the nonzeros' columns and counts, so that the sparse sums unroll with their indices known (a third faster than
    with them read from the arrays: the loop of `pattern`'s matrices only reads their values).
    Returns run(Mr, CT, KT, Br, Dr, Er, u, dt, params, state, k_start, out_q, out_v, out_a, out_f, out_z),
    arguments as ``newmark_loop``'s but for the state: `state` (P, 2 n_q + n_z) holds [q, v, z] of each system at
    sample max(k_start - 1, 0) on entry and at the last sample written on return, so that a record is integrated
    in time blocks (the outputs are samples k_start .. k_start + out_q.shape[1] - 1 of the whole record's road u),
    each block resuming where the one before ended, with the same numbers as one call (the rates at the resumed
    sample and the road's slopes are recomputed from the state and the road, as the one call had them). out_f and
    out_z of zero samples are not written. Compiled on first use, once per law and sizes, and cached on disk by
    numba (loaded in about 0.2 s instead of compiled in about six). (The law is part of the code: a law passed as
    an argument, as Newmark's loop takes it, cannot be inlined.)"""
    law, error_model = _inlined(force)
    key = _cache_key(force, error_model, nq, ns, nu, pattern)
    # compile-time constants of the loop (numba freezes the arrays a function closes over)
    (MC, MN), (BC, BN), (DC, DN), (EC, EN) = (_constants(cols, counts) for cols, counts in pattern)

    @numba.njit(inline="always", error_model=error_model)
    def rates(q, v, z, y, yd, Mr, CT, KT, Br, Dr, Er, par, d, dd, f, zd, rhs, a):  # pragma: no cover
        """``system_rates`` with this law."""
        strut_motion(q, v, y, yd, Dr, Er, d, dd)
        law(d, dd, z, par, f, zd)
        linear_rates(q, v, y, f, Mr, CT, KT, Br, Dr, rhs, a)

    @numba.njit(nogil=True, error_model=error_model)  # nogil: candidate fits run in parallel threads
    def run(
        Mr, CT, KT, Br, Dr, Er, u, dt, params, state, k_start, out_q, out_v, out_a, out_f, out_z
    ):  # pragma: no cover
        """Every system p of the batch, every step k from k_start, by classical RK4; see ``newmark_loop``.

        The rates are evaluated at two places, the stages and the current state (fewer copies of the inlined
        law: compile time), the stage-1 slopes of a step being the rates at the end of the step before. A block
        that resumes (k_start > 0) starts at sample k_start - 1 without a step: its rates there, as the block
        before ended with them."""
        P, n = out_q.shape[0], u.shape[1]
        nz = state.shape[1] - 2 * nq
        k_first, k_stop = max(k_start - 1, 0), k_start + out_q.shape[1]
        write_fz = out_f.shape[1] > 0
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
            if EN[i] > 0:
                road_drives_struts = True
        for p in range(P):
            r = 0 if u.shape[0] == 1 else p
            par = params[p]
            Mp, Bp = (MC, Mr[1][p], MN), (BC, Br[1][p], BN)  # the pattern's constants, this system's values
            Dp, Ep = (DC, Dr[1][p], DN), (EC, Er[1][p], EN)
            CTp, KTp = CT[p], KT[p]
            for i in range(nq):
                q[i] = state[p, i]
                v[i] = state[p, nq + i]
            for i in range(nz):
                z[i] = state[p, 2 * nq + i]
            for c in range(nu):
                slopes[c] = (u[r, 1, c] - u[r, 0, c]) / dt
                yd[c] = slopes[c]  # the slope at the first sample (later: of the step just taken)
            for k in range(k_first, k_stop):
                for c in range(nu):
                    y1[c] = u[r, k, c]
                if k > 0:
                    for c in range(nu):
                        y0c = u[r, k - 1, c]
                        yd[c] = (y1[c] - y0c) / dt
                        ym[c] = 0.5 * (y0c + y1[c])
                        if k < k_start:  # resuming: the slope the step into sample k left (as in one call)
                            slopes[c] = yd[c]
                if 0 < k and k >= k_start:  # a step from k - 1 to k (resuming at k_start - 1: none)
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
                    if not again and k >= k_start:
                        j = k - k_start
                        for i in range(nq):
                            out_q[p, j, i] = q[i]
                            out_v[p, j, i] = v[i]
                            out_a[p, j, i] = kv[0, i]
                        if write_fz:
                            for i in range(ns):
                                out_f[p, j, i] = f[i]
                            for i in range(nz):
                                out_z[p, j, i] = z[i]
            for i in range(nq):
                state[p, i] = q[i]
                state[p, nq + i] = v[i]
            for i in range(nz):
                state[p, 2 * nq + i] = z[i]

    if key is not None:
        run._cache = KeyedCache(run.py_func, key)  # numba's on-disk cache, under our own key
    return run
