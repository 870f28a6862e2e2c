"""The compiled loops behind the modal path's modes (``sim.modal._kept_modes``, ``sim.modal._second_order_modes``):
LAPACK's eigenvectors picked and their condition measured (``_pick_modes``), or the eigenvectors of a second-order
system and the rows of their inverse from its quadratic eigenproblem (``_quadratic_vectors``). Kept apart from
``sim.modal`` (the recursions, the projection and the paths that use them) for its size."""

from __future__ import annotations

import numpy as np

from ..core.jit import cached_njit


@cached_njit()
def _upper_first(lam_p, order):  # pragma: no cover - compiled
    """The modes' order: those with Im(lam) >= 0 first, then the rest, each in the order given (a stable argsort of
    Im(lam) < 0), written into `order`; returns how many come first."""
    count = 0
    for i in range(lam_p.size):
        if lam_p[i].imag >= 0:
            order[count] = i
            count += 1
    kept = count
    for i in range(lam_p.size):
        if lam_p[i].imag < 0:
            order[count] = i
            count += 1
    return kept


@cached_njit()
def _pick_modes(lam, V, W, lam_k, w_k, V_k, W_k, cond):  # pragma: no cover - compiled
    """Fill lam_k, w_k, V_k, W_k (see ``_kept_modes``) car by car: the modes with Im(lam) >= 0 in LAPACK's order,
    then padding (weight 0: the dropped modes in LAPACK's order, as a stable argsort of ~keep puts them);
    cond (P,) gets the 1-norm condition number ||V||_1 ||W||_1."""
    P, ns = lam.shape
    m = lam_k.shape[1]
    order = np.empty(ns, dtype=np.int64)
    for p in range(P):
        kept = _upper_first(lam[p], order)
        for j in range(m):
            i = order[j]
            lam_k[p, j] = lam[p, i]
            w_k[p, j] = 0.0 if j >= kept else (2.0 if lam[p, i].imag > 0 else 1.0)
            for r in range(ns):
                V_k[p, r, j] = V[p, r, i]
                W_k[p, j, r] = W[p, i, r]
        norm_v, norm_w = 0.0, 0.0
        for col in range(ns):
            sv, sw = 0.0, 0.0
            for r in range(ns):
                sv += abs(V[p, r, col])
                sw += abs(W[p, r, col])
            if not sv <= norm_v:  # (NaN propagates, as in NumPy's max)
                norm_v = sv
            if not sw <= norm_w:
                norm_w = sw
        cond[p] = norm_v * norm_w


SYMMETRY_TOL = 1e-14  # |X - X^T| / max|X| below which the left null vectors are taken for the right ones


@cached_njit()
def _cabs1(z):  # pragma: no cover - compiled
    """|Re z| + |Im z|: the pivots' and the scalings' measure (LAPACK's too), without hypot's cost."""
    return abs(z.real) + abs(z.imag)


@cached_njit()
def _abs2(z):  # pragma: no cover - compiled
    """|z|^2."""
    return z.real * z.real + z.imag * z.imag


@cached_njit()
def _lu_solve(Q, piv, b, transposed):  # pragma: no cover - compiled
    """Solve Q x = b (or Q^T x = b) in place in b, Q holding the LU factors of ``_quadratic_vectors`` (row swaps
    piv)."""
    d = Q.shape[0]
    if not transposed:
        for i in range(d):
            t = b[i]
            b[i] = b[piv[i]]
            b[piv[i]] = t
        for i in range(d):
            for j in range(i):
                b[i] -= Q[i, j] * b[j]
        for i in range(d - 1, -1, -1):
            for j in range(i + 1, d):
                b[i] -= Q[i, j] * b[j]
            b[i] /= Q[i, i]
    else:
        for i in range(d):
            for j in range(i):
                b[i] -= Q[j, i] * b[j]
            b[i] /= Q[i, i]
        for i in range(d - 1, -1, -1):
            for j in range(i + 1, d):
                b[i] -= Q[j, i] * b[j]
        for i in range(d - 1, -1, -1):
            t = b[i]
            b[i] = b[piv[i]]
            b[piv[i]] = t


@cached_njit()
def _null_vector(Q, piv, x, transposed):  # pragma: no cover - compiled
    """x (d,) <- the (left, when `transposed`) null vector of Q = LU (`piv`): two steps of inverse iteration from
    ones, each scaled to a largest |Re| + |Im| of 1."""
    x[:] = 1.0
    for _ in range(2):
        _lu_solve(Q, piv, x, transposed)
        big = 0.0
        for r in range(x.size):
            big = max(big, _cabs1(x[r]))
        for r in range(x.size if big > 0 else 0):
            x[r] /= big


@cached_njit()
def _quadratic_vectors(lam, M, C, K, lam_k, w_k, V_k, W_k, cond):  # pragma: no cover - compiled
    """Fill lam_k, w_k, V_k, W_k, cond (``_pick_modes``' layout) from the eigenvalues lam (P, 2 d) of the second-order
    systems (M, C, K) (P, d, d): the null vectors of Q(lam) = lam^2 M + lam C + K by two steps of inverse iteration
    each (Q's LU with partial pivoting, an exactly zero pivot replaced by eps |Q|), right and left (the
    right one when M, C, K are symmetric to SYMMETRY_TOL, as the car's are: an error of that order). Magnitudes are
    |Re| + |Im| where only a scale is wanted (complex abs, a hypot, had made this loop as slow as LAPACK's vectors)."""
    P, ns = lam.shape
    d = ns // 2
    m = lam_k.shape[1]
    order = np.empty(ns, dtype=np.int64)
    Q = np.empty((d, d), dtype=np.complex128)
    piv = np.empty(d, dtype=np.int64)
    v = np.empty(d, dtype=np.complex128)
    uu = np.empty(d, dtype=np.complex128)
    Mu, Cu, Ku = np.empty(d, dtype=np.complex128), np.empty(d, dtype=np.complex128), np.empty(d, dtype=np.complex128)
    colsum = np.empty(ns)
    for p in range(P):
        kept = _upper_first(lam[p], order)
        symmetric = True  # to round-off: the car's K and C come out of a matrix product a few ulps asymmetric
        scales = np.zeros(3)  # max |M|, |C|, |K|
        for i, X in enumerate((M[p], C[p], K[p])):
            for r in range(d):
                for c in range(d):
                    scales[i] = max(scales[i], abs(X[r, c]))
            for r in range(d):
                for c in range(r):
                    if abs(X[r, c] - X[c, r]) > SYMMETRY_TOL * scales[i]:
                        symmetric = False
        norm_v = 0.0
        colsum[:] = 0.0
        for j in range(m):
            s = lam[p, order[j]]
            weight = 0.0 if j >= kept else (2.0 if s.imag > 0 else 1.0)
            lam_k[p, j] = s
            w_k[p, j] = weight
            big = 0.0
            s2 = s * s
            for r in range(d):
                for c in range(d):  # real times complex in real arithmetic (numba would multiply two complexes)
                    m_, c_ = M[p, r, c], C[p, r, c]
                    Q[r, c] = complex(s2.real * m_ + s.real * c_ + K[p, r, c], s2.imag * m_ + s.imag * c_)
                    big = max(big, _cabs1(Q[r, c]))
            for c in range(d):  # LU, partial pivoting
                best, at = _cabs1(Q[c, c]), c
                for r in range(c + 1, d):
                    if _cabs1(Q[r, c]) > best:
                        best, at = _cabs1(Q[r, c]), r
                piv[c] = at
                if at != c:
                    for k in range(d):
                        t = Q[c, k]
                        Q[c, k] = Q[at, k]
                        Q[at, k] = t
                if Q[c, c] == 0:  # (compiled division by zero raises)
                    Q[c, c] = 2.220446049250313e-16 * big if big > 0 else 2.220446049250313e-16
                for r in range(c + 1, d):
                    f = Q[r, c] / Q[c, c]
                    Q[r, c] = f
                    for k in range(c + 1, d):
                        Q[r, k] -= f * Q[c, k]
            _null_vector(Q, piv, v, False)
            if symmetric:  # Q(lam)^T = Q(lam): the left null vector is the right one
                uu[:] = v
            else:
                _null_vector(Q, piv, uu, True)
            # x = [v, s v] at unit length; y = [(s M + C)^T u, M^T u] / (u^T (2 s M + C) v)
            length = 0.0
            for r in range(d):
                length += _abs2(v[r]) * (1.0 + _abs2(s))
            length = np.sqrt(length)
            for r in range(d):
                v[r] /= length
            # u^T Q(s) = 0 gives (s M + C)^T u = -K^T u / s: the form without cancellation where s M + C cancels
            # (a fast overdamped mode: s M ~ -C), the one with the smaller round-off bound of the two
            by_k = s != 0 and scales[2] / abs(s) < abs(s) * scales[0] + scales[1]
            for c in range(d):  # M^T u, C^T u, K^T u
                mu, cu, ku = 0.0j, 0.0j, 0.0j
                for r in range(d):
                    ur, ui = uu[r].real, uu[r].imag
                    mu += complex(M[p, r, c] * ur, M[p, r, c] * ui)
                    cu += complex(C[p, r, c] * ur, C[p, r, c] * ui)
                    ku += complex(K[p, r, c] * ur, K[p, r, c] * ui)
                Mu[c], Cu[c], Ku[c] = mu, cu, ku
            umv, ucv, ukv = 0.0j, 0.0j, 0.0j
            for c in range(d):
                umv += Mu[c] * v[c]
                ucv += Cu[c] * v[c]
                ukv += Ku[c] * v[c]
            denom = s * umv - ukv / s if by_k else 2.0 * s * umv + ucv  # u^T (2 s M + C) v = u^T (s M - K / s) v
            if denom == 0:  # a defective mode: W blows up, the candidate falls back
                denom = 1e-300 + 0.0j
            for c in range(d):
                top = -Ku[c] / s if by_k else s * Mu[c] + Cu[c]
                W_k[p, j, c] = top / denom
                W_k[p, j, d + c] = Mu[c] / denom
                V_k[p, c, j] = v[c]
                V_k[p, d + c, j] = s * v[c]
            if weight > 0:
                sv = 0.0
                for r in range(ns):
                    sv += np.sqrt(_abs2(V_k[p, r, j]))
                    colsum[r] += weight * np.sqrt(_abs2(W_k[p, j, r]))
                if not sv <= norm_v:
                    norm_v = sv
        norm_w = 0.0
        for r in range(ns):
            if not colsum[r] <= norm_w:
                norm_w = colsum[r]
        cond[p] = norm_v * norm_w
