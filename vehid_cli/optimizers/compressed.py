"""Least squares on a long residual through its compressed form: the trust region on D + 1 rows instead of R.

A long logger record gives R = 768 000 weighted residuals (60 s at 1 kHz, 16 channels) for D = 9 unknowns. The trust
region ('trf', trust_region.py) holds its Jacobian (R, D) about six times (its own copy, the scaled copy, the
augmented matrix, the SVD's input and its U: 55 MB each), which made the fit of a long record peak at nearly 800 MiB.
Its steps, though, depend on the Jacobian J and the residual r only through J'J, J'r and r'r. The thin QR of the
augmented matrix [J r] = Q [[Rj, z], [0, rho]] keeps exactly these: J'J = Rj'Rj, J'r = Rj'z, r'r = z'z + rho². So the
trust region runs on the compressed pair J_c = [Rj; 0] ((D + 1, D)) and f_c = [z; rho] ((D + 1,)), and gives the same
iterates as on (J, r), to round-off (tests/test_optimizers.py compares the two). The QR is accumulated over blocks of
rows (`compress`, a tall-skinny QR), so the only (R, D) array is the Jacobian itself, once.

The compressed residual is tied to the basis Q of the Jacobian at the same point, which the trust region asks for
only after it accepted a step. So `fun` returns a vector that carries the residual's norm alone (all the cost and
the step's acceptance need), and `jac` at that accepted point writes the residual's compressed coordinates into
that same array before the solver forms the gradient from it (`trust_region.trf_bounds`, the loop behind
`least_squares`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from .trust_region import trf_bounds

BLOCK_ROWS = 8192  # rows of [J r] per step of the blocked QR: 0.7 MB for D = 9


def compress(jt: NDArray, r: NDArray, block: int = BLOCK_ROWS) -> tuple[NDArray, NDArray, float]:
    """The compressed least-squares pair of the Jacobian `jt` (D, R) (transposed: row j is the residual's derivative
    by unknown j) and the residual r (R,): (Rj (D, D), z (D,), rho) with J'J = Rj'Rj, J'r = Rj'z and
    r'r = z'z + rho², the R factor of the QR of A = [J r] (R, D + 1).

    CholeskyQR2 over blocks of `block` rows: the Cholesky factor R1 of A'A with A's columns scaled to unit norm,
    then R2 of (A R1⁻¹)'(A R1⁻¹), R = R2 R1; as accurate as a Householder QR while A R1⁻¹ is well conditioned
    (scaled condition of A below about 1e7), and a matrix product per pass instead of LAPACK's column by column
    (0.06 s rather than 1.5 s for 768 000 x 10). Beyond that (the Cholesky fails, or A R1⁻¹ is still far from
    orthonormal) it falls back to a blocked Householder QR (`_householder`)."""
    D, R = jt.shape
    gram = np.zeros((D + 1, D + 1))
    for start in range(0, R, block):
        a = _block(jt, r, start, min(start + block, R))
        gram += a.T @ a
    try:
        r1 = _scaled_cholesky(gram)
        inverse = np.linalg.inv(r1)
        second = np.zeros((D + 1, D + 1))
        for start in range(0, R, block):
            q = _block(jt, r, start, min(start + block, R)) @ inverse
            second += q.T @ q
        if not np.all(np.isfinite(second)) or np.max(np.abs(second - np.eye(D + 1))) > 1e-2:
            raise np.linalg.LinAlgError("A R1^-1 is far from orthonormal")
        top = np.linalg.cholesky(second).T @ r1
    except np.linalg.LinAlgError:
        top = _householder(jt, r, block)
    return top[:D, :D], top[:D, D], float(abs(top[D, D]))


def compress_gram(G: NDArray) -> tuple[NDArray, NDArray, float] | None:
    """`compress` from the Gram matrix G = A'A (D + 1, D + 1) of A = [J r] summed without A (identify/forward.py):
    its Cholesky factor, A's columns scaled to unit norm first. One pass: J'J, J'r and r'r are G's to round-off, but
    the factor's accuracy is the Gram's (the square of A's scaled condition), where `compress`'s second pass restores
    a QR's. None where G is not positive definite (the caller then forms the Jacobian)."""
    D = G.shape[0] - 1
    try:
        top = _scaled_cholesky(G)
    except np.linalg.LinAlgError:
        return None
    return top[:D, :D], top[:D, D], float(abs(top[D, D]))


def _scaled_cholesky(G: NDArray) -> NDArray:
    """The upper Cholesky factor R of a Gram matrix G = A'A (R'R = G), A's columns scaled to unit norm before the
    factorisation and back after (a zero column left unscaled). Raises LinAlgError where G is not positive definite."""
    scale = np.sqrt(np.diag(G))
    scale[~(scale > 0)] = 1.0
    return np.linalg.cholesky(G / scale[:, None] / scale[None, :]).T * scale[None, :]


def _block(jt: NDArray, r: NDArray, start: int, stop: int) -> NDArray:
    """Rows start:stop of A = [J r] (stop - start, D + 1)."""
    a = np.empty((stop - start, jt.shape[0] + 1))
    a[:, :-1] = jt[:, start:stop].T
    a[:, -1] = r[start:stop]
    return a


def _householder(jt: NDArray, r: NDArray, block: int) -> NDArray:
    """The R factor (D + 1, D + 1) of [J r] by Householder QR over blocks of rows (a tall-skinny QR)."""
    D, R = jt.shape
    top = np.zeros((D + 1, D + 1))
    for start in range(0, R, block):
        top = np.linalg.qr(np.vstack([top, _block(jt, r, start, min(start + block, R))]), mode="r")
    return top


def trf_compressed(
    residual: Callable[[NDArray], NDArray],
    jacobian_rows: Callable[[NDArray], NDArray],
    x0: NDArray,
    lower: NDArray,
    upper: NDArray,
    x_scale: NDArray,
    tol: float,
    max_nfev: int | None = None,
    gram: Callable[[NDArray], NDArray | None] | None = None,
) -> NDArray:
    """The trust-region reflective least squares (`trust_region.least_squares`, x_scale=x_scale, xtol=ftol=gtol=tol)
    of `residual` (x -> (R,)) from x0 inside [lower, upper], its Jacobian given transposed by
    `jacobian_rows` (x -> (D, R), may be overwritten) and compressed (`compress`); returns the final point.
    x0 must be strictly inside the box (`make_strictly_feasible`).
    `gram(x)` (optional): the Gram matrix of [J r] at x summed without J (`compress_gram`), or None: then
    `jacobian_rows`."""

    D = x0.size
    last: dict[str, object] = {}

    def fun(x: NDArray) -> NDArray:
        r = residual(x)
        f = np.zeros(D + 1)
        f[0] = np.sqrt(np.dot(r, r))  # the cost 0.5 f'f is the residual's; its coordinates come with the Jacobian
        last["x"], last["f"] = x.copy(), f
        return f

    def jac(x: NDArray) -> NDArray:
        f = last["f"]
        if not np.array_equal(last["x"], x):  # the solver asks for the Jacobian at the point it evaluated last
            raise RuntimeError("trf asked for the Jacobian at a point other than its last residual's")
        got = None if gram is None else gram(x)
        pair = None if got is None else compress_gram(got)
        rj, z, rho = compress(jacobian_rows(x), residual(x)) if pair is None else pair
        f[:D] = z  # in place: the very array the solver holds as the residual at x
        f[D] = rho
        return np.vstack([rj, np.zeros((1, D))])

    f0 = fun(x0)
    j0 = jac(x0)
    return trf_bounds(fun, jac, x0, f0, j0, lower, upper, tol, tol, tol, max_nfev, np.asarray(x_scale, dtype=float))
