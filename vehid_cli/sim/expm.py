"""The matrix exponential of a stack of square matrices: scaling and squaring with the [13/13] Padé approximant
(N. J. Higham, SIAM J. Matrix Anal. Appl. 26 (2005) 1179-1193), the scaling chosen by ||A^k||^(1/k) as in Al-Mohy and
Higham (SIAM J. Matrix Anal. Appl. 31 (2009) 970-989).

Why not scipy.linalg.expm: the exact first-order-hold discretisation (``modal.foh_discretisation``) needs one, and
importing scipy.linalg (with the scipy._lib it pulls in) cost about 0.2 s of every command that simulates the car.
The [13/13] approximant of A / 2^s is exact to the unit round-off in exact arithmetic once ||A / 2^s|| <= theta_13;
squaring it s times gives exp(A). scipy's routine also picks lower degrees where they suffice and exploits
triangular structure; on the cars' Van Loan matrices the two are equally accurate (tests/test_expm.py, against a
long-double reference).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

THETA_13 = 5.371920351148152  # the largest 1-norm for which the [13/13] approximant is exact to round-off
PADE_13 = (
    64764752532480000.0, 32382376266240000.0, 7771770303897600.0, 1187353796428800.0, 129060195264000.0,
    10559470521600.0, 670442572800.0, 33522128640.0, 1323241920.0, 40840800.0, 960960.0, 16380.0, 182.0, 1.0,
)  # fmt: skip


def expm(A: NDArray) -> NDArray:
    """exp(A) of A (..., n, n), each matrix of the stack with its own scaling."""
    A = np.asarray(A, dtype=float)
    if A.ndim < 2 or A.shape[-1] != A.shape[-2]:
        raise ValueError(f"expm needs square matrices, got shape {A.shape}")
    if not np.all(np.isfinite(A)):
        raise ValueError("expm: the matrix has infs or NaNs")
    A2 = A @ A
    A4 = A2 @ A2
    A6 = A2 @ A4
    # Al-Mohy and Higham's (2009) scaling: by ||A^k||^(1/k) (k = 6, 8, exact here, the matrices being small) rather
    # than ||A||, which for a non-normal matrix (the Van Loan matrices: a large input block over a stable state
    # block) overstates how far the approximant must be scaled: each needless squaring costs accuracy
    alpha = np.maximum(_norm1(A6) ** (1 / 6), _norm1(A4 @ A4) ** (1 / 8))
    s = np.maximum(0, np.ceil(np.log2(np.maximum(alpha, 1e-300) / THETA_13))).astype(int)
    c = np.exp2(-s)[..., None, None]  # 2^-s: exact
    X, X2, X4, X6 = A * c, A2 * c**2, A4 * c**4, A6 * c**6
    b = PADE_13
    eye = np.broadcast_to(np.eye(A.shape[-1]), A.shape)
    U = X @ (X6 @ (b[13] * X6 + b[11] * X4 + b[9] * X2) + b[7] * X6 + b[5] * X4 + b[3] * X2 + b[1] * eye)
    V = X6 @ (b[12] * X6 + b[10] * X4 + b[8] * X2) + b[6] * X6 + b[4] * X4 + b[2] * X2 + b[0] * eye
    E = np.linalg.solve(V - U, V + U)
    for i in range(int(s.max(initial=0))):  # square each matrix its own s times
        more = s > i
        E = np.where(more[..., None, None], E @ E, E) if more.ndim else E @ E
    return E


def _norm1(A: NDArray) -> NDArray:
    """1-norms (largest absolute column sum) of a stack of matrices."""
    return np.abs(A).sum(axis=-2).max(axis=-1)
