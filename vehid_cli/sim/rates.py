"""The rates of a structure with struts (the models of `sim.kernel`): strut motion d = D q + E y, dd = D qd + E yd
from the state, and the accelerations M^-1 (B y - C qd - K q - D' f); the same arithmetic as dense loops, in the
same order, over the nonzeros of M^-1, B, D, E and the transposed C, K, so the speed-ups change no number."""

from __future__ import annotations

import numba

from ..core.jit import cached_njit


@cached_njit(inline="always")
def strut_motion(q, v, y, yd, Dr, Er, d, dd):  # pragma: no cover - compiled
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


@cached_njit(inline="always")
def linear_rates(q, v, y, f, Mr, CT, KT, Br, Dr, rhs, a):  # pragma: no cover - compiled
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
def system_rates(q, v, z, y, yd, Mr, CT, KT, Br, Dr, Er, force, par, d, dd, f, zd, rhs, a):  # pragma: no cover
    """Acceleration a and internal rates zd of one system at state (q, v, z) and road (y, yd); f gets the
    strut forces, d and dd the strut motion."""
    strut_motion(q, v, y, yd, Dr, Er, d, dd)
    force(d, dd, z, par, f, zd)
    linear_rates(q, v, y, f, Mr, CT, KT, Br, Dr, rhs, a)
