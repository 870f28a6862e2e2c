"""Fast exact first-order-hold simulation of the linear full car: modal recursions compiled with numba.

The exact FOH discretisation of sd = A s + Bs y (y linear between samples) is diagonal in the modal
coordinates of A = V diag(lam) V^-1: each mode is a scalar complex recursion

    z[k+1] = e z[k] + g1 . y[k] + g2 . (y[k+1] - y[k]),   e = exp(lam dt),
    g1 = dt phi1(lam dt) b,   g2 = dt phi2(lam dt) b,   b = row of V^-1 Bs,
    phi1(x) = (e^x - 1) / x,   phi2(x) = (e^x - 1 - x) / x^2,

which is the same update as ``foh_discretisation`` (the Van Loan matrix exponential), only cheaper. The
compiled loop runs it in x = z - g2 . y, which needs one input sample per step (x[k+1] = e x[k] + (g1 +
(e - 1) g2) . y[k]; ``_shifted``), and the projection adds the g2 . y back:
7 complex scalar recursions per car instead of a 14 x 14 matrix-vector product per step, and one
14 x 14 eigen-decomposition per car instead of a 22 x 22 matrix exponential: for the car, A's eigenvalues by a
compiled QR iteration (``sim.eigenvalues``: LAPACK's through numpy had cost twice as much) and its eigenvectors and
their inverse's rows from the 7 x 7 quadratic eigenproblem (lam^2 M + lam C + K) v = 0 (``_second_order_modes``;
LAPACK's vectors and the inverse had cost 40 % of the eigen-solve). A real system has
conjugate pairs, so only modes with Im(lam) >= 0 run, conjugates counted twice. Round-off grows with
the condition number of V; a candidate with an ill-conditioned V (a near-defective, e.g. near
critically damped, mode) goes through the real state-space recursion instead (``statespace_foh``,
same discretisation via the matrix exponential, ``sim.expm``, also compiled), so every candidate gets the exact answer.

Both paths start from static equilibrium on the first road sample, s0 = [K^-1 B y0, 0], like the
NumPy reference in ``sim.linear``.

The recursions run a block of cars at a time (``_modal_blocks``), and one matrix product per block turns the
block's modal coordinates into the output columns asked for: all of them for ``modal_foh`` (q, qd, qdd and every
body point), a layout's channels for ``modal_columns`` (identification reads 8 of 29), with the same numbers.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from ..core.jit import cached_njit
from ..models.fullcar import N_CORNERS, N_DOF, FullCarMatrices
from .eigenvalues import eigenvalues
from .expm import expm
from .modes import _pick_modes, _quadratic_vectors

N_STATE = 2 * N_DOF
COND_MAX = 1e8  # 1-norm condition number of V above which a candidate leaves the modal path (error ~ cond * 1e-16)
_SERIES_BELOW = 1e-2  # |lam dt| below which phi1, phi2 come from Taylor series (truncation < 1e-15 relative there)


def _phi12(x: NDArray) -> tuple[NDArray, NDArray]:
    """phi1(x) = (e^x - 1)/x and phi2(x) = (e^x - 1 - x)/x^2 for complex x, accurate near x = 0.

    The direct formulas everywhere, then the Taylor series where |x| < _SERIES_BELOW (few entries, often none):
    each entry is computed as by a select between the two over the whole array, at a fraction of its cost (the
    series' complex powers over every entry had cost a quarter of the gains' set-up of a 20-car batch)."""
    x = np.asarray(x)
    small = np.abs(x) < _SERIES_BELOW
    xs = np.where(small, 1.0, x) if small.any() else x  # keeps the direct formulas away from 0/0
    em1 = np.expm1(xs)
    phi1 = em1 / xs
    phi2 = (em1 - xs) / xs**2
    if small.any():
        z = x[small]
        phi1[small] = 1 + z / 2 + z**2 / 6 + z**3 / 24 + z**4 / 120 + z**5 / 720
        phi2[small] = 0.5 + z / 6 + z**2 / 24 + z**3 / 120 + z**4 / 720 + z**5 / 5040
    return phi1, phi2


LANE_GROUP = 4  # each car's modes are padded to a multiple of this many lanes (one AVX2 vector of doubles)


def _padded_modes(m: int) -> int:
    """Lanes per car in the recursion and its output: m modes padded to a multiple of LANE_GROUP."""
    return -(-m // LANE_GROUP) * LANE_GROUP


@cached_njit()
def _modal_recursion(e, g, x0, u, out):  # pragma: no cover - compiled
    """Run the modal recursions of P cars; out (P, n, 2 mp + 4) gets [Re x (mp), Im x (mp), y (4)] at each step,
    each car's rows contiguous, mp = ``_padded_modes(m)`` (the padding lanes stay 0).

    Lane p m + j of e, g, x0 is mode j of car p: x[k+1] = e x[k] + g . y[k], e (P m,) = exp(lam dt), g (4, P m) the
    gains of y[k] (``_shifted``), x0 (P m,) the start. u (R, n, 4), R = 1 (one road for all cars) or P.
    Time outside, all lanes of all cars inside: with one road the lane loop is a plain vector loop (SIMD), and
    the independent recursions overlap their latencies. Inside, each car has mp lanes (the padding: decay, gains
    and start 0), so that a car's lanes fill whole vectors and its output rows are whole vectors (2 mp + 4 = 20
    doubles for the car's 7 modes, 160 bytes): with each car's rows contiguous this ran recursion and projection
    1.15-1.3x faster than rows of 2 m + 4 interleaved over the block's cars (benchmarks/bench_modal_layout.py).
    """
    P = out.shape[0]
    m = e.shape[0] // P
    mp = (out.shape[2] - 4) // 2
    Lp = P * mp
    n = u.shape[1]
    one_road = u.shape[0] == 1
    er, ei, xr, xi = np.zeros(Lp), np.zeros(Lp), np.zeros(Lp), np.zeros(Lp)
    gr, gi = np.zeros((4, Lp)), np.zeros((4, Lp))
    for p in range(P):
        for j in range(m):
            s, d = p * m + j, p * mp + j
            er[d], ei[d] = e[s].real, e[s].imag
            xr[d], xi[d] = x0[s].real, x0[s].imag
            for c in range(4):
                gr[c, d], gi[c, d] = g[c, s].real, g[c, s].imag
    for k in range(n):
        y0, y1, y2, y3 = u[0, k, 0], u[0, k, 1], u[0, k, 2], u[0, k, 3]
        for p in range(P):  # the copies in loops of their own and y from scalars: they run as vector copies (the
            # loop that copied x's real and imaginary parts together, and y from u, had cost 1.4x the recursion)
            row = out[p, k]
            if not one_road:
                y0, y1, y2, y3 = u[p, k, 0], u[p, k, 1], u[p, k, 2], u[p, k, 3]
            for j in range(mp):
                row[j] = xr[p * mp + j]
            for j in range(mp):
                row[mp + j] = xi[p * mp + j]
            row[2 * mp], row[2 * mp + 1], row[2 * mp + 2], row[2 * mp + 3] = y0, y1, y2, y3
        if k == n - 1:
            break
        if one_road:  # y0..y3 still hold u[0, k] (read above, only overwritten with several roads)
            for l in range(Lp):
                dr = gr[0, l] * y0 + gr[1, l] * y1 + gr[2, l] * y2 + gr[3, l] * y3
                di = gi[0, l] * y0 + gi[1, l] * y1 + gi[2, l] * y2 + gi[3, l] * y3
                xr_new = er[l] * xr[l] - ei[l] * xi[l] + dr
                xi[l] = er[l] * xi[l] + ei[l] * xr[l] + di
                xr[l] = xr_new
        else:
            for l in range(Lp):
                r = l // mp
                dr = gr[0, l] * u[r, k, 0] + gr[1, l] * u[r, k, 1] + gr[2, l] * u[r, k, 2] + gr[3, l] * u[r, k, 3]
                di = gi[0, l] * u[r, k, 0] + gi[1, l] * u[r, k, 1] + gi[2, l] * u[r, k, 2] + gi[3, l] * u[r, k, 3]
                xr_new = er[l] * xr[l] - ei[l] * xi[l] + dr
                xi[l] = er[l] * xi[l] + ei[l] * xr[l] + di
                xr[l] = xr_new


@cached_njit()
def _statespace_recursion(Phi, G1, G2, s0, u, out):  # pragma: no cover - compiled
    """out (P, n, ns + 4) gets [s[k], y[k]] of s[k+1] = Phi s[k] + G1 y[k] + G2 (y[k+1] - y[k]), car by car."""
    P, ns = s0.shape
    n = u.shape[1]
    nu = u.shape[2]
    one_road = u.shape[0] == 1
    s = np.empty(ns)
    snew = np.empty(ns)
    for p in range(P):
        r = 0 if one_road else p
        for i in range(ns):
            s[i] = s0[p, i]
        for k in range(n):
            for i in range(ns):
                out[p, k, i] = s[i]
            for c in range(nu):
                out[p, k, ns + c] = u[r, k, c]
            if k == n - 1:
                break
            for i in range(ns):
                acc = 0.0
                for j in range(ns):
                    acc += Phi[p, i, j] * s[j]
                for c in range(nu):
                    yk = u[r, k, c]
                    acc += G1[p, i, c] * yk + G2[p, i, c] * (u[r, k + 1, c] - yk)
                snew[i] = acc
            for i in range(ns):
                s[i] = snew[i]


@cached_njit()
def propagate(Phi, s):  # pragma: no cover - compiled
    """s[k + 1] += Phi s[k] for k = 0 .. b - 2, in place: the free recursion of the states s (b, ns, K) of K input
    histories at once, each sample's driven part already in s. Phi s[k] is summed over j in order before it is
    added (as numpy's `s[k + 1] += Phi @ s[k]`, whose Python loop over the samples this replaces: ~3 us a sample at
    K = 50, most of a 3 s diagnosis's estimate of the unexplained force)."""
    b, ns, K = s.shape
    acc = np.empty(K)
    for k in range(b - 1):
        for i in range(ns):
            for c in range(K):
                acc[c] = 0.0
            for j in range(ns):
                w = Phi[i, j]
                for c in range(K):
                    acc[c] += w * s[k, j, c]
            for c in range(K):
                s[k + 1, i, c] += acc[c]


Outputs = tuple[NDArray, NDArray, NDArray, NDArray, NDArray]


def _flatten(mats: FullCarMatrices, road: NDArray, points: NDArray | None = None):
    """The batch flattened to P cars: batch shape, A (P, 14, 14), Bs (P, 14, 4), body points G (P, nb, 3) (the
    corners' when `points` is None), q0 (P, 7), u, and (M, C, K) (P, 7, 7) each."""
    G = mats.G if points is None else np.asarray(points, dtype=float)
    batch = mats.batch_shape
    if road.shape[:-2] not in ((), batch) or G.shape[:-2] not in ((), batch):  # (np.broadcast_shapes: 10 us)
        batch = np.broadcast_shapes(batch, road.shape[:-2], G.shape[:-2])
    P = math.prod(batch)
    n = road.shape[-2]

    def flat(X: NDArray) -> NDArray:
        Y = X if X.shape[:-2] == batch else np.broadcast_to(X, batch + X.shape[-2:])
        return Y.reshape((P,) + X.shape[-2:])

    A, Bs = mats.state_space()
    A, Bs, G, K, B = flat(A), flat(Bs), flat(G), flat(mats.K), flat(mats.B)
    MCK = (flat(mats.M), flat(mats.C), K)
    # Writeable and C-contiguous (copied if it is not): one array type for numba to compile.
    u = np.require(road.reshape(1, n, N_CORNERS) if road.ndim == 2 else flat(road), float, ["C", "W"])
    if u[:, 0, :].any():  # static equilibrium on the first road sample
        q0 = np.linalg.solve(K, B @ u[:, 0, :, None])[..., 0]
        q0 = q0 if q0.shape == (P, N_DOF) else np.broadcast_to(q0, (P, N_DOF))
    else:  # a road that starts at zero (the bumps): the solve's zeros, without its cost (a fifth of the set-up)
        q0 = np.zeros((P, N_DOF))
    return batch, A, Bs, G, q0, u, MCK


def _n_out(G: NDArray) -> int:
    """Output columns for nb body points: q, qd, qdd (7 each), disp and acc (nb each)."""
    return 3 * N_DOF + 2 * G.shape[-2]


def _input_rows(Bs: NDArray, G: NDArray) -> NDArray:
    """Rows (P, 4, 21 + 2 nb) of the output projection fed by the road y: qdd gets Bs y, acc gets G (Bs y)[:3]."""
    P, nb = Bs.shape[0], G.shape[-2]
    rows = np.zeros((P, N_CORNERS, _n_out(G)))
    Bq = Bs[:, N_DOF:, :]  # (P, 7, 4)
    rows[:, :, 2 * N_DOF : 3 * N_DOF] = np.swapaxes(Bq, -1, -2)
    rows[:, :, 3 * N_DOF + nb :] = np.swapaxes(G @ Bq[:, :3, :], -1, -2)
    return rows


def _statespace_projection(A: NDArray, Bs: NDArray, G: NDArray) -> NDArray:
    """(P, 18, 21 + 2 nb): [s, y] -> [q, qd, qdd, disp, acc] with qdd = (A s + Bs y)[7:], disp = G q[:3],
    acc = G qdd[:3]."""
    P, nb = A.shape[0], G.shape[-2]
    proj = np.zeros((P, N_STATE + N_CORNERS, _n_out(G)))
    proj[:, :N_STATE, :N_STATE] = np.eye(N_STATE)
    Aq = A[:, N_DOF:, :]  # (P, 7, 14)
    proj[:, :N_STATE, N_STATE : 3 * N_DOF] = np.swapaxes(Aq, -1, -2)
    proj[:, :N_DOF, 3 * N_DOF : 3 * N_DOF + nb][:, :3, :] = np.swapaxes(G, -1, -2)
    proj[:, :N_STATE, 3 * N_DOF + nb :] = np.swapaxes(G @ Aq[:, :3, :], -1, -2)
    proj[:, N_STATE:, :] = _input_rows(Bs, G)
    return proj


def _split(Y: NDArray, batch: tuple[int, ...]) -> Outputs:
    """(P, n, 21 + 2 nb) -> q, qd, qdd (batch..., n, 7), disp, acc (batch..., n, nb)."""
    Y = Y.reshape(batch + Y.shape[-2:])
    d, nb = N_DOF, (Y.shape[-1] - 3 * N_DOF) // 2
    return Y[..., :d], Y[..., d : 2 * d], Y[..., 2 * d : 3 * d], Y[..., 3 * d : 3 * d + nb], Y[..., 3 * d + nb :]


def foh_discretisation(A: NDArray, Bs: NDArray, dt: float) -> tuple[NDArray, NDArray, NDArray]:
    """Phi, G1, G2 with s[k+1] = Phi s[k] + G1 u[k] + G2 (u[k+1] - u[k]) for u linear over the step.

    From exp of [[A, B, 0], [0, 0, I/dt], [0, 0, 0]] dt (Van Loan): the input and its constant slope
    ride along as extra states.
    """
    n, m = A.shape[-1], Bs.shape[-1]
    batch = A.shape[:-2]
    big = np.zeros(batch + (n + 2 * m, n + 2 * m))
    big[..., :n, :n] = A * dt
    big[..., :n, n : n + m] = Bs * dt
    big[..., n : n + m, n + m :] = np.eye(m)
    E = expm(big)
    return E[..., :n, :n], E[..., :n, n : n + m], E[..., :n, n + m :]


def _statespace_outputs(A: NDArray, Bs: NDArray, G: NDArray, q0: NDArray, u: NDArray, dt: float) -> NDArray:
    """(P, n, 21 + 2 nb) outputs of the real state-space recursion for P cars."""
    P, n = A.shape[0], u.shape[1]
    Phi, G1, G2 = foh_discretisation(A, Bs, dt)
    s0 = np.zeros((P, N_STATE))
    s0[:, :N_DOF] = q0
    out = np.empty((P, n, N_STATE + N_CORNERS))
    _statespace_recursion(np.ascontiguousarray(Phi), np.ascontiguousarray(G1), np.ascontiguousarray(G2), s0, u, out)
    return out @ _statespace_projection(A, Bs, G)


def statespace_foh(mats: FullCarMatrices, road: NDArray, dt: float, points: NDArray | None = None) -> Outputs:
    """q, qd, qdd (batch..., n, 7), disp, acc (batch..., n, nb) at the body `points` (..., nb, 3) (default the
    corners'): exact FOH via the matrix exponential (``sim.expm``), real 14-state recursion.

    The same discretisation as the NumPy reference, with the time loop compiled; kept as the modal
    path's fallback and as a benchmark competitor.
    """
    batch, A, Bs, G, q0, u, _ = _flatten(mats, road, points)
    return _split(_statespace_outputs(A, Bs, G, q0, u, dt), batch)


def modal_foh(mats: FullCarMatrices, road: NDArray, dt: float, points: NDArray | None = None) -> Outputs:
    """q, qd, qdd (batch..., n, 7) [m, rad, /s, /s²], disp, acc (batch..., n, nb) at the body `points` (..., nb, 3)
    (rows [1, y, -x]; default the four corners'): the exact FOH, mode by mode.

    Candidates whose eigenvector matrix has a 1-norm condition number above COND_MAX go through the
    real state-space recursion instead; the answer is the same discretisation either way.
    """
    batch, A, Bs, G, q0, u, MCK = _flatten(mats, road, points)
    (Y,) = _modal_columns(A, Bs, G, q0, u, dt, [np.arange(_n_out(G))], MCK)
    return _split(Y, batch)


def modal_columns(
    mats: FullCarMatrices, road: NDArray, dt: float, groups: Sequence[Sequence[int]], points: NDArray | None = None
) -> list[NDArray]:
    """Only some output columns of ``modal_foh``, the same numbers: one array (batch..., n, len(group)) per group of
    column indices into [q (7), qd (7), qdd (7), disp (nb), acc (nb)] (``column_index``).

    An identification reads a few channels (the paper's: 8 of 29 columns), and projecting the modal coordinates
    onto the columns is most of the work: each group is computed straight into its own contiguous array."""
    batch, A, Bs, G, q0, u, MCK = _flatten(mats, road, points)
    Ys = _modal_columns(A, Bs, G, q0, u, dt, [np.asarray(g, dtype=int) for g in groups], MCK)
    return [Y.reshape(batch + Y.shape[-2:]) for Y in Ys]


FIELD_OFFSETS = {"q": 0, "qd": N_DOF, "qdd": 2 * N_DOF, "disp": 3 * N_DOF}  # acc follows disp's nb columns


def column_index(field: str, index: int, nb: int) -> int:
    """The column of ``field`` (q, qd, qdd, disp, acc) [index] among [q, qd, qdd, disp, acc] for nb body points."""
    return 3 * N_DOF + nb + index if field == "acc" else FIELD_OFFSETS[field] + index


def _modal_columns(
    A: NDArray,
    Bs: NDArray,
    G: NDArray,
    q0: NDArray,
    u: NDArray,
    dt: float,
    groups: list[NDArray],
    MCK: tuple[NDArray, NDArray, NDArray] | None = None,
) -> list[NDArray]:
    """(P, n, len(group)) for each group of output columns of P cars: modal recursions, then the projection. With
    the car's (M, C, K) the modes come from ``_second_order_modes`` (A's eigenvalues only), else ``_kept_modes``."""
    P, n = A.shape[0], u.shape[1]
    if MCK is None:
        lam_k, w_k, V_k, W_k, good = _kept_modes(A)  # (P, m), (P, m), (P, 14, m), (P, m, 14), (P,)
    else:
        lam_k, w_k, V_k, W_k, good = _second_order_modes(A, *MCK)
    m = lam_k.shape[1]
    bm = W_k @ Bs  # (P, m, 4): modal input matrix
    z0 = (W_k[:, :, :N_DOF] @ q0[:, :, None])[..., 0]  # (P, m)
    decay, a, b = _foh_gains(lam_k, bm, dt)

    # Output j-th mode column: w_j [V_j, lam_j V_j[7:], G V_j[:3], G lam_j V_j[7:10]]; Re(c z) = Re c Re z - Im c Im z.
    # Only the columns asked for are weighted and split (the same numbers as selecting them afterwards).
    qdd_modes = lam_k[:, None, :] * V_k[:, N_DOF:, :]
    c = np.concatenate([V_k, qdd_modes, G @ V_k[:, :3, :], G @ qdd_modes[:, :3, :]], axis=1)  # (P, 21 + 2 nb, m)
    rows = _input_rows(Bs, G)
    columns, views = _gemm_columns(groups, rows.shape[-1])
    if columns is not None:
        c, rows = c[:, columns, :], rows[:, :, columns]
    ct = np.swapaxes(c * w_k[:, None, :], -1, -2)  # (P, m, ncol)
    proj = np.concatenate([ct.real, -ct.imag, rows], axis=1)
    Y = np.empty((P, n, proj.shape[-1]))
    _modal_blocks(decay, a, b, z0.reshape(P * m), u, proj, Y)
    if not good.all():
        for block in _blocks(np.flatnonzero(~good), n, N_STATE + N_CORNERS):
            ub = u if u.shape[0] == 1 else np.ascontiguousarray(u[block])
            full = _statespace_outputs(A[block], Bs[block], G[block], q0[block], ub, dt)
            Y[block] = full if columns is None else full[..., columns]
    return [Y[..., view] for view in views]


GEMM_WIDTH = 8  # the projection's columns are padded to a multiple of this (see _gemm_columns)


def _gemm_columns(groups: list[NDArray], n_out: int) -> tuple[NDArray | None, list[slice]]:
    """The columns one projection computes for all `groups` (None: all n_out of them, in order) and each group's
    slice of them.

    One product for every group, padded (with copies of its last column) to a multiple of GEMM_WIDTH columns:
    OpenBLAS sums each entry of the product in the same order as for the whole response then, so a group's
    numbers are those of ``modal_foh`` bit for bit; a product of 1-4 columns (mod 8) sums in another order
    (round-off apart, measured with OpenBLAS 0.3.31, Haswell kernels)."""
    views, start = [], 0
    for g in groups:
        views.append(slice(start, start + g.size))
        start += g.size
    columns = [int(c) for g in groups for c in g]
    if columns == list(range(n_out)):
        return None, views
    if columns:
        columns += [columns[-1]] * (-len(columns) % GEMM_WIDTH)
    return np.array(columns, dtype=int), views


SCRATCH_BYTES = 32 * 2**20  # a block's states over the whole record, at most (the state-space path: fewer cars)
CARS_PER_BLOCK = 8  # cars whose recursions run together (see _modal_blocks)
BLOCK_BYTES = 4 * 2**20  # a block's modal coordinates, at most: 8 cars over 3000 samples, a long record in time blocks


def _block_size(n: int, width: int) -> int:
    """Cars per block for n samples of `width` columns each: CARS_PER_BLOCK, fewer when their scratch would pass
    SCRATCH_BYTES."""
    return max(1, min(CARS_PER_BLOCK, SCRATCH_BYTES // (8 * n * width)))


def _blocks(cars: NDArray, n: int, width: int) -> list[NDArray]:
    """`cars` (indices) in blocks of _block_size."""
    size = _block_size(n, width)
    return [cars[i : i + size] for i in range(0, cars.size, size)]


def _shifted(decay: NDArray, a: NDArray, b: NDArray, z0: NDArray, u: NDArray, proj: NDArray):
    """The recursion in x = z - b . y, which needs one input sample per step: x[k+1] = e x[k] + g . y[k],
    g = e b + a (from z[k+1] = e z[k] + a . y[k] + b . y[k+1]). Returns g (4, P m), x0 (P m,) and the projection
    `proj` (P, 2 m + 4, ncol) onto [Re x, Im x, y] in the recursion's padded rows (P, 2 mp + 4, ncol),
    [Re x (mp), Im x (mp), y], the padding's rows 0: z = x + b . y adds Re(c b) to the rows of y."""
    P, m = proj.shape[0], decay.size // proj.shape[0]
    mp = _padded_modes(m)
    g = decay * b + a
    y0 = u[:, 0, :] if u.shape[0] == 1 else np.repeat(u[:, 0, :], m, axis=0)  # (1 or P m, 4)
    x0 = z0 - (b.T * y0).sum(axis=-1)
    bc = b.reshape(b.shape[0], P, m).transpose(1, 0, 2)  # (P, 4, m)
    re, im = proj[:, :m, :], proj[:, m : 2 * m, :]
    shifted = np.zeros((P, 2 * mp + b.shape[0], proj.shape[-1]))
    shifted[:, :m], shifted[:, mp : mp + m] = re, im
    np.add(proj[:, 2 * m :, :], bc.real @ re + bc.imag @ im, out=shifted[:, 2 * mp :, :])
    return g, x0, shifted


def _modal_blocks(decay: NDArray, a: NDArray, b: NDArray, z0: NDArray, u: NDArray, proj: NDArray, out) -> None:
    """Run the modal recursions (`_foh_gains`' decay, gains a, b, start z0 over P m lanes, roads u) a block of cars
    at a time and project each block at once: out[p] = [Re z, Im z, y] @ proj[p], proj (P, 2 m + 4, ncol) (the
    recursion runs in x = z - b . y: ``_shifted``; its rows are padded to mp modes: ``_modal_recursion``).

    Why blocks: the lane loop needs several cars to fill its SIMD vectors (one car, 7 lanes, ran 3x slower per
    car), but all of a batch's modal coordinates at once (100 cars: 43 MB) fall out of cache between the
    recursion that writes them and the projection that reads them: batch 100 ran 2x slower per car than batch
    20 did. CARS_PER_BLOCK = 8 (56 lanes, 3.5 MB for 3000 samples) was the fastest of 2 to 100 at 8 and 29
    columns. A long record runs in time blocks of BLOCK_BYTES (a 60 s record's coordinates are 10 MB per car), each
    started from the state its predecessor stored for its last sample. Each car's numbers are the same whatever the
    blocks, and the padding's zero rows of the projection add exact zeros: the same numbers as without it."""
    P = out.shape[0]
    g, x0, padded = _shifted(decay, a, b, z0, u, proj)
    m = decay.size // P
    mp = (padded.shape[1] - b.shape[0]) // 2
    n, width = u.shape[1], padded.shape[1]
    count = -(-P // min(P, CARS_PER_BLOCK))
    size = -(-P // count)  # blocks of nearly equal size: 20 cars run as 7, 7, 6 rather than 8, 8, 4
    rows = max(2, min(n, BLOCK_BYTES // (8 * width * size)))  # samples per block: a long record's in several
    buffer = np.empty(size * rows * width)  # a smaller last block in the same memory: a new 3 MB array each call
    # cost its page faults (20 cars as 7, 7, 6 ran 2x slower per car than 21 as 7, 7, 7)
    for start in range(0, P, size):
        stop = min(P, start + size)
        lanes = slice(start * m, stop * m)
        ub = u if u.shape[0] == 1 else u[start:stop]
        x, k0 = x0[lanes], 0
        while True:  # each time block ends on the next one's first sample, whose state starts that block
            k1 = min(n, k0 + rows)
            block = buffer[: (stop - start) * (k1 - k0) * width].reshape(stop - start, k1 - k0, width)
            _modal_recursion(decay[lanes], g[:, lanes], x, np.ascontiguousarray(ub[:, k0:k1]), block)
            np.matmul(block, padded[start:stop], out=out[start:stop, k0:k1])
            if k1 == n:
                break
            x = np.empty(x.shape, dtype=complex)  # the state at k1 - 1 as the recursion stored it: the same numbers
            x.real, x.imag = block[:, -1, :m].reshape(-1), block[:, -1, mp : mp + m].reshape(-1)
            k0 = k1 - 1


def _kept_modes(A: NDArray) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray]:
    """The modes of each state matrix A (P, ns, ns) the recursion runs on: eigenvalues with Im > 0 (weight 2: the
    conjugate adds the same real part) and real ones (weight 1), first and padded to one count m with weight 0;
    their eigenvalues (P, m), weights (P, m), eigenvectors (P, ns, m), rows of the inverse (P, m, ns), and whether
    the eigenvector matrix is well conditioned (P,). LAPACK returns conjugate pairs exactly conjugate.

    The picking and the condition numbers run compiled (``_pick_modes``): as a dozen NumPy calls they had cost a
    fifth of a 20-car batch's set-up (the same numbers: copies, and the condition only compared to COND_MAX)."""
    lam, V = np.linalg.eig(A)
    lam, V = lam.astype(complex, copy=False), V.astype(complex, copy=False)
    W = np.linalg.inv(V)
    m = int((lam.imag >= 0).sum(axis=-1).max())
    P, ns = lam.shape
    lam_k, w_k = np.empty((P, m), dtype=complex), np.empty((P, m))
    V_k, W_k = np.empty((P, ns, m), dtype=complex), np.empty((P, m, ns), dtype=complex)
    cond = np.empty(P)
    _pick_modes(lam, V, W, lam_k, w_k, V_k, W_k, cond)
    good = np.isfinite(cond) & (cond < COND_MAX)
    return lam_k, w_k, V_k, W_k, good


def _second_order_modes(
    A: NDArray, M: NDArray, C: NDArray, K: NDArray
) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray]:
    """``_kept_modes`` of A = [[0, I], [-M^-1 K, -M^-1 C]] (P, 2 d, 2 d) from its eigenvalues alone (``eigenvalues``,
    compiled): what LAPACK's eigenvectors and the inverse of their matrix had cost (two fifths of the eigen-solve)
    comes from the d x d quadratic eigenproblem (lam^2 M + lam C + K) v = 0 instead (``_quadratic_vectors``, compiled).

    Right eigenvector [v, lam v] (unit length, as LAPACK's), left one [(lam M + C)^T u, M^T u] with u^T Q(lam) = 0,
    scaled so that it is the row of the inverse: y . x = u^T (2 lam M + C) v = 1. Modes of distinct eigenvalues are
    biorthogonal, so these are the rows of V^-1; a near-defective mode makes the normalisation (and the condition
    number ||V||_1 ||V^-1||_1, from the kept modes: a conjugate has the same magnitudes) blow up, and the candidate
    goes through the state-space recursion like any ill-conditioned one. The same modes as LAPACK's to round-off."""
    lam_k, w_k, V_k, W_k, cond = _quadratic_modes(A, M, C, K)
    good = np.isfinite(cond) & (cond < COND_MAX)
    return lam_k, w_k, V_k, W_k, good


def _quadratic_modes(A: NDArray, M: NDArray, C: NDArray, K: NDArray) -> tuple[NDArray, ...]:
    """``_second_order_modes``' modes with the condition numbers (P,) in place of the verdict."""
    lam = eigenvalues(A)
    m = int((lam.imag >= 0).sum(axis=-1).max())
    P, ns = lam.shape
    lam_k, w_k = np.empty((P, m), dtype=complex), np.empty((P, m))
    V_k, W_k = np.empty((P, ns, m), dtype=complex), np.empty((P, m, ns), dtype=complex)
    cond = np.empty(P)
    _quadratic_vectors(lam, M, C, K, lam_k, w_k, V_k, W_k, cond)
    return lam_k, w_k, V_k, W_k, cond


def _foh_gains(lam_k: NDArray, bm: NDArray, dt: float) -> tuple[NDArray, NDArray, NDArray]:
    """The modal recursion's per-step decay exp(lam dt) (P m,) and its first-order-hold gains on this sample's and
    the next sample's input, (inputs, P m) each, from the modal input matrix bm (P, m, inputs)."""
    P, m, inputs = bm.shape
    x = lam_k * dt
    phi1, phi2 = _phi12(x)
    bt = bm.transpose(2, 0, 1)  # (inputs, P, m): the products come out in the gains' order, no copies after
    g2 = (dt * phi2) * bt
    a = (dt * phi1) * bt - g2
    return np.exp(x).reshape(P * m), a.reshape(inputs, P * m), g2.reshape(inputs, P * m)


MAX_MODAL_INPUTS = 4  # the modal recursion's inputs per step (fewer are padded with zeros: a zero adds nothing)


def linear_foh(A: NDArray, Bs: NDArray, s0: NDArray, u: NDArray, dt: float, Cy: NDArray, Dy: NDArray) -> NDArray:
    """Outputs y = Cy s + Dy u (P, n, ny) of sd = A s + Bs u for any linear system, exact for u linear between
    samples (first-order hold): the modal recursions of the full car, generic over the state size.

    A (P, ns, ns), Bs (P, ns, nu), s0 (P, ns) the start, u (n, nu) one input for all or (P, n, nu), Cy (P, ny, ns),
    Dy (P, ny, nu). Candidates with an ill-conditioned eigenvector matrix (or more than MAX_MODAL_INPUTS inputs) go
    through the real state-space recursion: the same discretisation either way."""
    P, nu = A.shape[0], Bs.shape[-1]
    u3 = np.array(u[None] if u.ndim == 2 else u, dtype=float, order="C")
    n = u3.shape[1]
    drive = (u3 @ np.swapaxes(Dy, -1, -2)) if Dy.size else 0.0  # (P or 1, n, ny) feedthrough
    if nu > MAX_MODAL_INPUTS:
        return _statespace_linear(A, Bs, s0, u3, dt, Cy) + drive
    lam_k, w_k, V_k, W_k, good = _kept_modes(A)  # (P, m), (P, m), (P, ns, m), (P, m, ns), (P,)
    m = lam_k.shape[1]
    bm = np.zeros((P, m, MAX_MODAL_INPUTS), dtype=complex)
    bm[..., :nu] = W_k @ Bs
    z0 = (W_k @ s0[:, :, None])[..., 0]
    decay, a, b = _foh_gains(lam_k, bm, dt)
    padded = np.zeros(u3.shape[:2] + (MAX_MODAL_INPUTS,))
    padded[..., :nu] = u3
    ct = np.swapaxes((Cy @ V_k) * w_k[:, None, :], -1, -2)  # (P, m, ny)
    proj = np.zeros((P, 2 * m + MAX_MODAL_INPUTS, ct.shape[-1]))  # Dy u enters through `drive`
    proj[:, :m], proj[:, m : 2 * m] = ct.real, -ct.imag
    Y = np.empty((P, n, proj.shape[-1]))
    _modal_blocks(decay, a, b, z0.reshape(P * m), padded, proj, Y)
    if not good.all():
        for block in _blocks(np.flatnonzero(~good), n, A.shape[-1] + nu):
            ub = u3 if u3.shape[0] == 1 else np.ascontiguousarray(u3[block])
            Y[block] = _statespace_linear(A[block], Bs[block], s0[block], ub, dt, Cy[block])
    return Y + drive


def _statespace_linear(A: NDArray, Bs: NDArray, s0: NDArray, u: NDArray, dt: float, Cy: NDArray) -> NDArray:
    """(P, n, ny) Cy s of the real state-space recursion (exact FOH via ``sim.expm``), compiled."""
    P, ns = s0.shape
    n, nu = u.shape[1], u.shape[2]
    Phi, G1, G2 = foh_discretisation(A, Bs, dt)
    out = np.empty((P, n, ns + nu))
    _statespace_recursion(
        np.ascontiguousarray(Phi), np.ascontiguousarray(G1), np.ascontiguousarray(G2),
        np.ascontiguousarray(s0, dtype=float), u, out,
    )  # fmt: skip
    return out[..., :ns] @ np.swapaxes(Cy, -1, -2)
