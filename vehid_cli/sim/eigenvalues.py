"""Eigenvalues of a batch of small real matrices, compiled: what the modal path of the linear car solves once per
candidate (its 14 x 14 state matrix), at about half of LAPACK's cost for that size.

EISPACK's route (Wilkinson & Reinsch, Handbook for Automatic Computation II; Numerical Recipes 11.5-11.6): the
matrix balanced by powers of two (exact, ``_balance``), reduced to upper Hessenberg form by stabilised elimination
(``_hessenberg``), then Francis' double-shift QR iteration deflating one real eigenvalue or a conjugate pair at a
time (``_francis``). A pair comes out exactly conjugate (x +- i y from the same x and y), a real eigenvalue with an
imaginary part of exactly 0, as LAPACK's. Called through numpy, LAPACK's dgeev spends most of its ~30 us on a
14 x 14 matrix in the same QR iteration plus its call overhead; this takes ~14 us (benchmarks/bench_simulation.py).
The eigenvalues agree with LAPACK's to ~1e-14 relative (tests/test_eigenvalues.py); a matrix whose iteration does
not converge, or that is not finite, is left to LAPACK.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray

from ..core.jit import cached_njit

RADIX = 2.0  # balancing scales by powers of the floating-point radix: no rounding
MAX_ITERATIONS = 30  # QR iterations per eigenvalue before the matrix is handed to LAPACK


def eigenvalues(A: NDArray) -> NDArray:
    """The eigenvalues (P, n) complex of the real matrices A (P, n, n), each in the order the QR iteration deflates
    them (bottom up), as ``np.linalg.eigvals`` would give them to round-off; LAPACK's for any matrix this iteration
    leaves (not finite: LAPACK's error, as before)."""
    A = np.ascontiguousarray(A, dtype=float)
    P, n = A.shape[0], A.shape[-1]
    lam = np.empty((P, n), dtype=complex)
    ok = np.empty(P, dtype=np.bool_)
    _eigenvalues(A, lam, ok)
    if not ok.all():
        lam[~ok] = np.linalg.eigvals(A[~ok])
    return lam


@cached_njit()
def _eigenvalues(A, lam, ok):  # pragma: no cover - compiled
    """lam[p] <- the eigenvalues of A[p] (P, n, n); ok[p] False (lam[p] unset) where A[p] is not finite or the QR
    iteration did not converge."""
    P, n = A.shape[0], A.shape[1]
    a = np.empty((n + 1, n + 1))  # the working copy, indexed from 1 as in the Handbook's algorithms
    wr, wi = np.empty(n), np.empty(n)
    for p in range(P):
        finite = True
        for i in range(n):
            for j in range(n):
                a[i + 1, j + 1] = A[p, i, j]
                finite &= math.isfinite(A[p, i, j])
        ok[p] = finite
        if not finite:
            continue
        _balance(a, n)
        _hessenberg(a, n)
        ok[p] = _francis(a, n, wr, wi)
        for i in range(n):
            lam[p, i] = complex(wr[i], wi[i])


@cached_njit()
def _balance(a, n):  # pragma: no cover - compiled
    """Balance a[1:, 1:] in place (EISPACK balanc without permutations): row i divided and column i multiplied by a
    power of two until the off-diagonal norms of each row and its column are within a factor of two. A similarity
    transform without rounding; it makes the QR iteration's errors scale with the balanced norm."""
    square = RADIX * RADIX
    done = False
    while not done:
        done = True
        for i in range(1, n + 1):
            r = c = 0.0
            for j in range(1, n + 1):
                if j != i:
                    c += abs(a[j, i])
                    r += abs(a[i, j])
            if c == 0.0 or r == 0.0:
                continue
            g = r / RADIX
            f = 1.0
            s = c + r
            while c < g:
                f *= RADIX
                c *= square
            g = r * RADIX
            while c > g:
                f /= RADIX
                c /= square
            if (c + r) / f < 0.95 * s:
                done = False
                g = 1.0 / f
                for j in range(1, n + 1):
                    a[i, j] *= g
                for j in range(1, n + 1):
                    a[j, i] *= f


@cached_njit()
def _hessenberg(a, n):  # pragma: no cover - compiled
    """Reduce a[1:, 1:] to upper Hessenberg form in place by Gaussian elimination with pivoting (EISPACK elmhes),
    a similarity transform; the multipliers are left below the subdiagonal (``_francis`` clears what it reads)."""
    for m in range(2, n):
        x = 0.0
        i = m
        for j in range(m, n + 1):  # the pivot: the largest entry of column m - 1 at or below row m
            if abs(a[j, m - 1]) > abs(x):
                x = a[j, m - 1]
                i = j
        if i != m:
            for j in range(m - 1, n + 1):
                a[i, j], a[m, j] = a[m, j], a[i, j]
            for j in range(1, n + 1):
                a[j, i], a[j, m] = a[j, m], a[j, i]
        if x == 0.0:
            continue
        for i in range(m + 1, n + 1):
            y = a[i, m - 1]
            if y != 0.0:
                y /= x
                a[i, m - 1] = y
                for j in range(m, n + 1):
                    a[i, j] -= y * a[m, j]
                for j in range(1, n + 1):
                    a[j, m] += y * a[j, i]


@cached_njit()
def _francis(a, n, wr, wi):  # pragma: no cover - compiled
    """The eigenvalues wr + i wi (n,) of the upper Hessenberg a[1:, 1:] by Francis' double-shift QR iteration (EISPACK
    hqr), a destroyed. Deflates at a negligible subdiagonal entry (one whose addition to its diagonal neighbours'
    magnitudes changes nothing), one real eigenvalue or a 2 x 2 block's pair at a time; exceptional shifts after
    10 and 20 iterations. Returns False after MAX_ITERATIONS without deflation."""
    anorm = 0.0  # for the deflation test where the two diagonal entries vanish
    for i in range(1, n + 1):
        for j in range(max(i - 1, 1), n + 1):
            anorm += abs(a[i, j])
    nn = n  # the active block is a[l:nn+1, l:nn+1]
    t = 0.0  # the exceptional shifts applied so far
    while nn >= 1:
        its = 0
        while True:
            l = 1
            for k in range(nn, 1, -1):  # the lowest negligible subdiagonal entry splits the matrix
                s = abs(a[k - 1, k - 1]) + abs(a[k, k])
                if s == 0.0:
                    s = anorm
                if abs(a[k, k - 1]) + s == s:
                    a[k, k - 1] = 0.0
                    l = k
                    break
            x = a[nn, nn]
            if l == nn:  # one real eigenvalue
                wr[nn - 1], wi[nn - 1] = x + t, 0.0
                nn -= 1
                break
            y = a[nn - 1, nn - 1]
            w = a[nn, nn - 1] * a[nn - 1, nn]
            if l == nn - 1:  # a 2 x 2 block: a real pair or a conjugate pair
                p = 0.5 * (y - x)
                q = p * p + w
                z = math.sqrt(abs(q))
                x += t
                if q >= 0.0:
                    z = p + (z if p >= 0.0 else -z)
                    wr[nn - 2] = wr[nn - 1] = x + z
                    if z != 0.0:
                        wr[nn - 1] = x - w / z
                    wi[nn - 2] = wi[nn - 1] = 0.0
                else:
                    wr[nn - 2] = wr[nn - 1] = x + p
                    wi[nn - 2], wi[nn - 1] = z, -z
                nn -= 2
                break
            if its == MAX_ITERATIONS:
                return False
            if its == 10 or its == 20:  # exceptional shift
                t += x
                for i in range(1, nn + 1):
                    a[i, i] -= x
                s = abs(a[nn, nn - 1]) + abs(a[nn - 1, nn - 2])
                x = y = 0.75 * s
                w = -0.4375 * s * s
            its += 1
            _double_shift_step(a, l, nn, x, y, w)
    return True


@cached_njit()
def _double_shift_step(a, l, nn, x, y, w):  # pragma: no cover - compiled
    """One implicit double-shift QR step on the active block a[l:nn+1, l:nn+1] with the shifts whose sum and product
    are x + y and x y - w (the trailing 2 x 2 block's eigenvalues): it starts at the lowest row m where two
    consecutive small subdiagonal entries allow it, and chases the bulge down with 3 x 3 Householder reflections."""
    p = q = r = z = 0.0
    m = nn - 2
    while m >= l:  # the first column of (H - s1)(H - s2) from row m, and where it may start
        z = a[m, m]
        r = x - z
        s = y - z
        p = (r * s - w) / a[m + 1, m] + a[m, m + 1]
        q = a[m + 1, m + 1] - z - r - s
        r = a[m + 2, m + 1]
        s = abs(p) + abs(q) + abs(r)
        p /= s
        q /= s
        r /= s
        if m == l:
            break
        u = abs(a[m, m - 1]) * (abs(q) + abs(r))
        v = abs(p) * (abs(a[m - 1, m - 1]) + abs(z) + abs(a[m + 1, m + 1]))
        if u + v == v:
            break
        m -= 1
    for i in range(m + 2, nn + 1):  # elimination multipliers and old bulges below the subdiagonal
        a[i, i - 2] = 0.0
        if i != m + 2:
            a[i, i - 3] = 0.0
    for k in range(m, nn):
        if k != m:  # the bulge's column
            p = a[k, k - 1]
            q = a[k + 1, k - 1]
            r = a[k + 2, k - 1] if k != nn - 1 else 0.0
            x = abs(p) + abs(q) + abs(r)
            if x != 0.0:
                p /= x
                q /= x
                r /= x
        s = math.sqrt(p * p + q * q + r * r)
        if p < 0.0:
            s = -s
        if s == 0.0:
            continue
        if k == m:
            if l != m:
                a[k, k - 1] = -a[k, k - 1]
        else:
            a[k, k - 1] = -s * x
        p += s
        x = p / s
        y = q / s
        z = r / s
        q /= p
        r /= p
        for j in range(k, nn + 1):  # the reflection from the left, on rows k .. k + 2
            p = a[k, j] + q * a[k + 1, j]
            if k != nn - 1:
                p += r * a[k + 2, j]
                a[k + 2, j] -= p * z
            a[k + 1, j] -= p * y
            a[k, j] -= p * x
        for i in range(l, min(nn, k + 3) + 1):  # and from the right, on columns k .. k + 2
            p = x * a[i, k] + y * a[i, k + 1]
            if k != nn - 1:
                p += z * a[i, k + 2]
                a[i, k + 2] -= p * r
            a[i, k + 1] -= p * q
            a[i, k] -= p
