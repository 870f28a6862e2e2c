"""Exact sensitivities of the first-order-hold simulation of a linear system: d output / d parameter.

For sd = A s + Bs u, y = Cy s + Dy u, the derivative s' = ds/dtheta obeys the same dynamics,
s'd = A s' + A' s + Bs' u, s'(0) = s0'. In the modal coordinates of A = V diag(lam) W (zeta = W s', z = W s):

    zeta_j' = lam_j zeta_j + sum_i F_ji z_i + (W Bs')_j u,   F = W A' V,

whose solution is a combination of a few signals per mode j (all of them first-order-hold exact, because the
simulator's recursion is the continuous solution for an input linear between samples):

* xi_jc, mode j's response to a unit of input c from rest, and f_j = exp(lam_j t), its free response;
* d xi_jc / d lam_j and d f_j / d lam_j (the scalar recursion differentiated: d[k+1] = e d[k] + e' z[k] +
  a'.y[k] + b'.y[k+1], e' = dt e);
* for i != j, mode i driving mode j gives F_ji / (lam_i - lam_j) (z_i - x_ji), where x_ji is mode j run with
  mode i's input row and start (the eigenvector derivative of first-order perturbation theory); for i = j it
  gives F_jj dz_j / dlam_j.

So the cost is (inputs + 1) pairs of scalar recursions per mode whatever the number of parameters, and every
output's derivative is one real matrix product of these signals. The output matrices' derivatives (Cy', Dy')
and the start's (s0') come from the caller. A candidate whose eigenvalues nearly coincide (the perturbation
formulas divide by their gaps) or whose eigenvector matrix is ill conditioned is flagged, for the caller's
central differences.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from ..core.jit import cached_njit
from ..models.fullcar import N_DOF
from .lumped import lumped_state_space, sample_slopes
from .modal import _kept_modes, _phi12

ASSEMBLY_STEP = 1e-6  # relative step of the central differences of the matrices' assembly (polynomial or rational
# in the parameters: relative error ~1e-10)
GAP_MIN = 1e-6  # smallest |lam_i - lam_j| relative to max |lam| the perturbation formulas are trusted at
Sink = Callable[[int, int, NDArray, NDArray], None]  # (candidate, first sample, outputs (b, ny), dy (b, ny, D))
BLOCK = 4096  # samples of a record per block of linear_sensitivities (its modal states carried across blocks)
SINK_BLOCK = 1024  # ... at most, when the blocks go to a sink: its temporaries 16 MB at 60 s x 16 channels x 9
# unknowns, 42 MB at 4096 (tracemalloc), for the same wall to the noise of the measurement (issue 26)
_SERIES_BELOW = 1e-2  # |lam dt| below which the derivatives of phi1, phi2 come from Taylor series


def _dphi12(x: NDArray, phi12: tuple[NDArray, NDArray] | None = None) -> tuple[NDArray, NDArray]:
    """phi1'(x) = (e^x - phi1)/x and phi2'(x) = (phi1 - 2 phi2)/x, accurate near x = 0 (series); `phi12`: phi1(x),
    phi2(x) when the caller has them."""
    phi1, phi2 = _phi12(x) if phi12 is None else phi12
    small = np.abs(x) < _SERIES_BELOW
    xs = np.where(small, 1.0, x)
    d1 = np.where(small, 1 / 2 + x / 3 + x**2 / 8 + x**3 / 30 + x**4 / 144 + x**5 / 840, (np.exp(xs) - phi1) / xs)
    d2 = np.where(small, 1 / 6 + x / 12 + x**2 / 40 + x**3 / 180 + x**4 / 1008 + x**5 / 6720, (phi1 - 2 * phi2) / xs)
    return d1, d2


@cached_njit()
def _sensitivity_recursion(e, zs, ws, cz, drive, zout, wout):  # pragma: no cover - compiled
    """Each mode's recursion z[k+1] = e z[k] + drive_z[k] (lane l = p m + j: mode j of candidate p; e (P m,))
    and, driven by it, D lanes per mode w[k+1] = e w[k] + drive_w[k] + cz z[k] (lane q = (p D + d) m + j; cz
    (P D m,)). zs (2, P m) and ws (2, P D m) hold [Re; Im] of the start states and get the end states (one block
    of a record carries them to the next). drive (n or n - 1, 2 (P m + P D m)): [Re, Im] of each lane's input
    term (the gains times y[k] and y[k + 1], one matrix product outside), z lanes first; with n rows the states
    step past the block's last sample (to the next block's first), with n - 1 they end at it.

    zout (n, P, 2 m) gets [Re z, Im z] of the candidate's m modes, wout (n, P, D, 2 m) [Re w, Im w] of each
    parameter's (both C-contiguous)."""
    n = zout.shape[0]
    L = e.shape[0]
    P = zout.shape[1]
    m = L // P
    Q = cz.shape[0]
    D = Q // L
    N = L + Q  # lanes; drive's real parts in columns 0..N-1, imaginary parts in N..2N-1
    steps = drive.shape[0]
    er, ei = e.real.copy(), e.imag.copy()
    zr, zi = zs[0].copy(), zs[1].copy()
    wr, wi = ws[0].copy(), ws[1].copy()
    cr, ci = cz.real.copy(), cz.imag.copy()
    ar, ai = np.empty(Q), np.empty(Q)  # e of each parameter lane's mode, and that mode's z at the step: the
    zqr, zqi = np.empty(Q), np.empty(Q)  # parameter lanes then run as one flat loop (no gathers in it)
    lane = np.empty(Q, dtype=np.int64)
    for p in range(P):
        for d in range(D):
            for j in range(m):
                lane[(p * D + d) * m + j] = p * m + j
    for q in range(Q):
        ar[q] = er[lane[q]]
        ai[q] = ei[lane[q]]
    z2 = zout.reshape(n, P * 2 * m)  # (C-contiguous) each step's outputs as one row: plain offsets into it
    w2 = wout.reshape(n, Q * 2)
    for k in range(n):
        zk = z2[k]
        wk = w2[k]
        for p in range(P):
            for j in range(m):
                zk[2 * p * m + j] = zr[p * m + j]
                zk[2 * p * m + m + j] = zi[p * m + j]
            for d in range(D):
                first = (p * D + d) * m
                for j in range(m):
                    wk[2 * first + j] = wr[first + j]
                    wk[2 * first + m + j] = wi[first + j]
        if k >= steps:
            break
        dk = drive[k]
        for q in range(Q):
            zqr[q] = zr[lane[q]]
            zqi[q] = zi[lane[q]]
        for q in range(Q):
            fr = cr[q] * zqr[q] - ci[q] * zqi[q] + dk[L + q]
            fi = cr[q] * zqi[q] + ci[q] * zqr[q] + dk[N + L + q]
            new = ar[q] * wr[q] - ai[q] * wi[q] + fr
            wi[q] = ar[q] * wi[q] + ai[q] * wr[q] + fi
            wr[q] = new
        for l in range(L):
            a = er[l]
            b = ei[l]
            new = a * zr[l] - b * zi[l] + dk[l]
            zi[l] = a * zi[l] + b * zr[l] + dk[N + l]
            zr[l] = new
    zs[0] = zr
    zs[1] = zi
    ws[0] = wr
    ws[1] = wi


def linear_sensitivities(
    A: NDArray, Bs: NDArray, s0: NDArray, u: NDArray, dt: float, Cy: NDArray, Dy: NDArray,
    dA: NDArray, dBs: NDArray, ds0: NDArray, dCy: NDArray, dDy: NDArray, block: int = BLOCK,
    sink: Sink | None = None,
) -> tuple[NDArray, NDArray | None, NDArray]:  # fmt: skip
    """Outputs y = Cy s + Dy u (P, n, ny) of sd = A s + Bs u (exact first-order hold, like ``modal.linear_foh``)
    and their derivatives (P, n, ny, D; a view of (P, n, D, ny)) with respect to D parameters, and which
    candidates (P,) they hold for.

    A (P, ns, ns), Bs (P, ns, nu), s0 (P, ns), u (n, nu) one input for all, Cy (P, ny, ns), Dy (P, ny, nu), and the
    derivatives dA (P, D, ns, ns), dBs (P, D, ns, nu), ds0 (P, D, ns), dCy (P, D, ny, ns), dDy (P, D, ny, nu). A
    candidate with an ill-conditioned eigenvector matrix or nearly repeated eigenvalues gets False: its numbers are
    not to be used (central differences instead).

    The record runs in blocks of `block` samples, the modal states carried from one to the next: nothing of the
    size of the derivatives is held beside the result (the same numbers as one block, to round-off). With `sink`,
    the derivatives are not kept: each block's are handed to `sink(p, k0, y, dy)` (candidate p, first sample k0, its
    outputs y (b, ny) and derivatives dy (b, ny, D); blocks of at most SINK_BLOCK) as they are made, and None is
    returned in their place (a long record's normal equations summed without its (n, ny, D) array,
    `optimizers.normal`)."""
    lam, w, V, W, good = _kept_modes(A)  # (P, m), (P, m), (P, ns, m), (P, m, ns), (P,)
    P, m = lam.shape
    nu, D, ny = Bs.shape[-1], dA.shape[1], Cy.shape[1]
    bm = W @ Bs  # (P, m, nu)
    z0 = (W @ s0[:, :, None])[..., 0]  # (P, m)
    valid, pair = w > 0, w == 2
    lamF = np.concatenate([lam, lam.conj()], axis=-1)  # every mode: the kept ones, then the conjugates of pairs
    validF = np.concatenate([valid, pair], axis=-1)
    bmF = np.concatenate([bm, bm.conj()], axis=1)
    z0F = np.concatenate([z0, z0.conj()], axis=1)
    VF = np.concatenate([V, V.conj()], axis=-1)
    Fk = W[:, None] @ dA @ VF[:, None]  # (P, D, m, 2m): F = W A' V, rows of the kept modes
    gap = lamF[:, None, :] - lam[:, :, None]  # (P, m, 2m) lam_i - lam_j
    couple = validF[:, None, :] & valid[:, :, None]
    couple[:, np.arange(m), np.arange(m)] = False
    scale = np.abs(lam).max(axis=-1)
    close = couple & (np.abs(gap) <= GAP_MIN * scale[:, None, None])
    ok = good & ~np.any(close, axis=(1, 2))
    couple &= ~close  # a refused candidate's numbers stay finite (and unused)
    kappa = np.where(couple[:, None], Fk / np.where(couple, gap, 1.0)[:, None], 0.0)  # (P, D, m, 2m)
    Fjj = Fk[..., np.arange(m), np.arange(m)] * valid[:, None]  # (P, D, m)

    coef_u = W[:, None] @ dBs - kappa @ bmF[:, None]  # (P, D, m, nu): on xi_jc
    coef_f = (W[:, None] @ ds0[..., None])[..., 0] - (kappa @ z0F[:, None, :, None])[..., 0]  # (P, D, m): on f_j
    Gk = (Cy @ V) * w[:, None, :]  # (P, ny, m)
    Q = Gk[:, None] @ kappa  # (P, D, ny, 2m): through z_i of every mode i
    Qt = Q[..., :m] + Q[..., m:].conj() + (dCy @ V[:, None]) * w[:, None, None, :]  # + Cy' s
    # Parameter d's lane of mode j: w = sum_c coef_u xi_jc + coef_f f_j + F_jj dz_j/dlam_j, one recursion driven
    # by z_j (the lam-derivative's de z term); then dy = Re(Gk w) + Re(Qt z) + dDy u.
    x = lam * dt
    phi1, phi2 = _phi12(x)
    d1, d2 = _dphi12(x, (phi1, phi2))
    e = np.exp(x)
    al, be = dt * (phi1 - phi2), dt * phi2  # (P, m) FOH gains per unit input on y[k], y[k + 1]
    dal, dbe = dt * dt * (d1 - d2), dt * dt * d2  # and their lam-derivatives
    ga = al[:, None, :, None] * coef_u + (Fjj * dal[:, None])[..., None] * bm[:, None]  # (P, D, m, nu)
    gb = be[:, None, :, None] * coef_u + (Fjj * dbe[:, None])[..., None] * bm[:, None]

    def lanes(g: NDArray) -> NDArray:  # (..., nu) -> (nu, lanes) contiguous
        return np.ascontiguousarray(np.moveaxis(g, -1, 0).reshape(nu, -1))

    gains = np.concatenate(  # (2 nu, lanes): on y[k], then on y[k + 1]; the z lanes, then the parameters'
        [np.concatenate([lanes(al[..., None] * bm), lanes(ga)], axis=1),
         np.concatenate([lanes(be[..., None] * bm), lanes(gb)], axis=1)]
    )  # fmt: skip
    G = np.concatenate([gains.real, gains.imag], axis=1)  # (2 nu, 2 lanes)
    zs = np.stack([z0.real.reshape(-1), z0.imag.reshape(-1)])  # (2, P m): the states carried across blocks
    ws = np.stack([coef_f.real.reshape(-1), coef_f.imag.reshape(-1)])  # (2, P D m)
    cz = (Fjj * (dt * e)[:, None]).reshape(-1)
    Rz = np.concatenate([Gk, Qt.reshape(P, D * ny, m)], axis=1).transpose(0, 2, 1)  # (P, m, ny (1 + D))
    Rz = np.concatenate([Rz.real, -Rz.imag], axis=1)  # (P, 2m, ny (1 + D)): Re(c z) = Re c Re z - Im c Im z
    Rg = np.concatenate([Gk.real, -Gk.imag], axis=-1).transpose(0, 2, 1)  # (P, 2m, ny)
    dDyl = dDy.transpose(0, 3, 1, 2).reshape(P, nu, D * ny)  # (P, nu, D ny): dy (d, o)
    block = block if sink is None else min(block, SINK_BLOCK)
    Y, dY = _blocks(e.reshape(-1), zs, ws, cz, G, u, Dy, dDyl, Rz, Rg, (m, D, ny), block, sink)
    return Y, dY, ok


def _blocks(
    e: NDArray, zs: NDArray, ws: NDArray, cz: NDArray, G: NDArray, u: NDArray, Dy: NDArray, dDyl: NDArray,
    Rz: NDArray, Rg: NDArray, sizes: tuple[int, int, int], block: int, sink: Sink | None = None,
) -> tuple[NDArray, NDArray | None]:  # fmt: skip
    """`linear_sensitivities`' recursion and projections, `block` samples at a time, the states zs, ws carried.

    The derivatives are held as (P, n, D, ny), where each product lands contiguous, and returned as the view
    (P, n, ny, D): no pass that transposes them (a caller that copies a family's channels out transposes there).
    With `sink`, each block's derivatives go to it as they are made (a (b, ny, D) view of one reused buffer, to be
    consumed before it returns) and none are kept."""
    m, D, ny = sizes
    P, n = Dy.shape[0], u.shape[0]
    Y = np.empty((P, n, ny))
    dYt = np.empty((P, n, D, ny)) if sink is None else None
    scratch = None if sink is None else np.empty((max(2, int(block)), D, ny))
    block = max(2, int(block))
    for k0 in range(0, n, block):
        k1 = min(n, k0 + block)
        b = k1 - k0
        ub = u[k0 : min(n, k1 + 1)]  # the block's inputs and the next block's first (the step to it)
        drive = np.concatenate([ub[:-1], ub[1:]], axis=1) @ G  # (b or b - 1, 2 lanes)
        zout = np.empty((b, P, 2 * m))
        wout = np.empty((b, P, D, 2 * m))
        _sensitivity_recursion(e, zs, ws, cz, drive, zout, wout)
        for p in range(P):  # the sums written straight into their places (no temporaries of the derivatives' size)
            Z = zout[:, p] @ Rz[p]  # (b, ny (1 + D)): the outputs, then dy (d, o)
            np.add(Z[:, :ny], u[k0:k1] @ Dy[p].T, out=Y[p, k0:k1])
            held = dYt[p, k0:k1] if sink is None else scratch[:b]  # contiguous: the reshape is a view
            dy = held.reshape(b * D, ny)
            np.matmul(wout[:, p].reshape(b * D, 2 * m), Rg[p], out=dy)
            dy += Z[:, ny:].reshape(b * D, ny)
            dy += (u[k0:k1] @ dDyl[p]).reshape(b * D, ny)
            if sink is not None:
                sink(p, k0, Y[p, k0:k1], held.transpose(0, 2, 1))
    return Y, (None if dYt is None else dYt.transpose(0, 1, 3, 2))


def car_output_matrices(A: NDArray, Bs: NDArray, G: NDArray) -> tuple[NDArray, NDArray]:
    """The full car's response columns [q, qd, qdd, disp, acc] (21 + 2 nb, like ``modal_foh``) as Cy s + Dy y:
    Cy (..., 21 + 2 nb, 14), Dy (..., 21 + 2 nb, 4), from A, Bs and the body points' rows G (..., nb, 3)."""
    batch, nb = A.shape[:-2], G.shape[-2]
    ns, nu = A.shape[-1], Bs.shape[-1]
    Cy = np.zeros(batch + (3 * N_DOF + 2 * nb, ns))
    Dy = np.zeros(batch + (3 * N_DOF + 2 * nb, nu))
    Cy[..., : 2 * N_DOF, :] = np.eye(ns)
    Cy[..., 2 * N_DOF : 3 * N_DOF, :] = A[..., N_DOF:, :]
    Dy[..., 2 * N_DOF : 3 * N_DOF, :] = Bs[..., N_DOF:, :]
    Cy[..., 3 * N_DOF : 3 * N_DOF + nb, :3] = G
    Cy[..., 3 * N_DOF + nb :, :] = G @ A[..., N_DOF : N_DOF + 3, :]
    Dy[..., 3 * N_DOF + nb :, :] = G @ Bs[..., N_DOF : N_DOF + 3, :]
    return Cy, Dy


def central_points(values: NDArray, h: NDArray) -> NDArray:
    """(2D, D) candidates: `values` (D,) with +h_j on parameter j (rows 0..D-1), then with -h_j (rows D..2D-1): the
    points of central differences."""
    values = np.asarray(values, dtype=float)
    D = values.size
    X = np.repeat(values[None, :], 2 * D, axis=0)
    X[np.arange(D), np.arange(D)] += h
    X[D + np.arange(D), np.arange(D)] -= h
    return X


def stencil(values: NDArray, rel_step: float = ASSEMBLY_STEP) -> tuple[NDArray, NDArray]:
    """The central-difference points (2D + 1, D) of D parameters at `values` — the centre, then +h_j, then -h_j on
    parameter j — and the steps h (D,), `rel_step` of each value: where the (cheap) assembly of the matrices is
    evaluated for their derivatives (`central_slopes`)."""
    values = np.asarray(values, dtype=float)
    h = rel_step * np.maximum(np.abs(values), 1e-12)
    return np.concatenate([values[None, :], central_points(values, h)]), h


def central_slopes(Z: NDArray, h: NDArray) -> NDArray:
    """(1, D, ...) derivatives from a stack Z (2D + 1, ...) of the centre, then +h_j, then -h_j on parameter j."""
    D = h.size
    return ((Z[1 : D + 1] - Z[D + 1 :]) / (2 * h.reshape((D,) + (1,) * (Z.ndim - 1))))[None]


def lumped_sensitivities(
    M: NDArray, C: NDArray, K: NDArray, B0: NDArray, B1: NDArray, u: NDArray, dt: float, Sq: NDArray, Sa: NDArray,
    h: NDArray,
) -> tuple[NDArray, NDArray, NDArray, NDArray] | None:  # fmt: skip
    """A lumped rig's displacement and acceleration outputs (n, kd), (n, ka) (``lumped.lumped_outputs``) and their
    derivatives (n, kd, D), (n, ka, D) with respect to D parameters; None where the modal formulas do not hold.

    The matrices M, C, K, B0, B1 (2D + 1, d, ...) and sensor rows Sq, Sa are those of the rig, then with +h_j, then
    -h_j on parameter j: their derivatives are central differences of the (cheap) assembly, the dynamics' are exact.
    u (n, nu) one input."""
    A, Bs, s0, Cy, Dy, Ey = lumped_state_space(M, C, K, B0, B1, u[0], Sq, Sa)
    Y, dY, ok = linear_sensitivities(
        A[:1], Bs[:1], s0[:1], u, dt, Cy[:1], Dy[:1], central_slopes(A, h), central_slopes(Bs, h),
        central_slopes(s0, h), central_slopes(Cy, h), central_slopes(Dy, h),
    )  # fmt: skip
    if not ok[0]:
        return None
    kd = Sq.shape[-2]
    slopes = sample_slopes(u, dt)  # (n, nu)
    acc = Y[0, :, kd:] + slopes @ Ey[0].T
    dacc = dY[0, :, kd:] + np.einsum("nc,doc->nod", slopes, central_slopes(Ey, h)[0])
    return Y[0, :, :kd], acc, dY[0, :, :kd], dacc
