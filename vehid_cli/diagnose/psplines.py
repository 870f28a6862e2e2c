"""P-splines: cubic B-spline bases constrained to vanish at 0 with their roughness penalty, and the penalised
least squares with one smoothing parameter per penalised block chosen by REML (or GCV).

* A basis over the range of some values has knots halfway between the values' quantiles and equal spacing
  (dense where the data are, still reaching the sparse extremes); its columns vanish at 0, and its penalty is
  the integrated squared second derivative (exact 2-point Gauss quadrature per knot interval), whose null space,
  the straight line through 0, is free.
* ``penalised_fit`` solves min |r - A c|² + sum_j lambda_j c_j' P_j c_j from the normal equations, each lambda_j
  relative to its block's own scale, and returns the coefficients, their unscaled covariance (A'A + P_lambda)^-1,
  the effective degrees of freedom (the hat matrix' trace) and tr(2 H - H H).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.optimize
from numpy.typing import NDArray
from scipy.interpolate import BSpline

LOG_LAMBDA = (-7.0, 8.0)  # search range of log10 lambda relative to the basis' own scale


@dataclass(frozen=True)
class Basis:
    """A cubic B-spline basis on [t[3], t[-4]] constrained to vanish at 0 (columns B Z), with its penalty."""

    t: NDArray
    Z: NDArray  # (nb, nb - 1)
    P: NDArray  # (nb - 1, nb - 1): integral of (second derivative)² in the constrained coefficients

    @property
    def size(self) -> int:
        return self.Z.shape[1]

    def __call__(self, x: NDArray) -> NDArray:
        """(len(x), size) constrained basis at x (clipped into the knot span)."""
        lo, hi = self.t[3], self.t[-4]
        xc = np.clip(np.asarray(x, dtype=float).ravel(), lo, hi)
        B = BSpline.design_matrix(xc, self.t, 3).toarray()
        return B @ self.Z


def basis(values: NDArray, n_knots: int) -> Basis:
    """Knots halfway between the values' quantiles and equal spacing over their range (dense where the data
    are, still reaching the sparse extremes); 0 kept inside the span."""
    v = np.asarray(values, dtype=float).ravel()
    lo, hi = min(float(np.min(v)), 0.0), max(float(np.max(v)), 0.0)
    span = hi - lo
    if not span > 0:
        raise ValueError("the strut does not move: no force law can be estimated from this trajectory")
    lo, hi = lo - 1e-6 * span, hi + 1e-6 * span
    p = np.linspace(0.0, 1.0, n_knots + 2)[1:-1]
    inner = 0.5 * (np.quantile(v, p) + lo + p * (hi - lo))
    inner = np.unique(inner[(inner > lo) & (inner < hi)])
    t = np.r_[[lo] * 4, inner, [hi] * 4]
    nb = t.size - 4
    # penalty: exact 2-point Gauss quadrature per knot interval (B'' is linear on each)
    edges = np.unique(t)
    a, b = edges[:-1], edges[1:]
    g = np.array([-1.0, 1.0]) / math.sqrt(3.0)
    xq = (0.5 * (a + b)[:, None] + 0.5 * (b - a)[:, None] * g[None, :]).ravel()
    wq = np.repeat(0.5 * (b - a), 2)
    d2 = BSpline(t, np.eye(nb), 3).derivative(2)(xq)  # (nq, nb)
    P = d2.T @ (wq[:, None] * d2)
    c = BSpline.design_matrix(np.array([0.0]), t, 3).toarray()[0]
    Q, _ = np.linalg.qr(c[:, None], mode="complete")
    Z = Q[:, 1:]
    return Basis(t=t, Z=Z, P=Z.T @ P @ Z)


@dataclass(frozen=True)
class PenalisedFit:
    """The solution of `penalised_fit`: coefficients, their covariance factor, the smoothing parameters chosen."""

    coef: NDArray
    cov: NDArray  # (A'A + P_lambda)^-1 in the original column units
    lam: NDArray  # per penalised block
    edf: float  # trace of the hat matrix
    rss: float
    edf2: float  # tr(2 H - H H): the reference degrees of freedom of the test


def penalised_fit(
    AtA: NDArray, Atr: NDArray, rtr: float, R: int, blocks: list[tuple[slice, NDArray]], criterion: str = "reml"
) -> PenalisedFit:
    """min |r - A c|² + sum_j lam_j c_j' P_j c_j, the lam_j by REML (default) or GCV.

    REML: the restricted likelihood with the scale profiled out, (R - M0) log(RSS + c' P_lam c) + log|H|
    - sum_j rank_j log lam_j, H = A'A + P_lam, M0 the penalty's null-space dimension; GCV: R RSS / (R - edf)².
    """
    scale = np.sqrt(np.maximum(np.diag(AtA), 1e-300))
    As = AtA / np.outer(scale, scale)
    bs = Atr / scale
    m = As.shape[0]
    Ps, ranks = [], []
    for sl, P in blocks:
        Pj = np.zeros((m, m))
        Pj[sl, sl] = P / np.outer(scale[sl], scale[sl])
        Pj /= max(np.trace(Pj) / (sl.stop - sl.start), 1e-300)  # lam = 1: penalty on the scale of the data term
        ev = np.linalg.eigvalsh(Pj[sl, sl])
        ranks.append(int(np.sum(ev > 1e-9 * ev.max())))
        Ps.append(Pj)
    ridge = 1e-9 * np.eye(m)
    null = m - sum(ranks)

    def fit(rho: NDArray):
        Pl = sum((10.0**r * P for r, P in zip(rho, Ps, strict=True)), np.zeros((m, m)))
        H = As + ridge + Pl
        try:
            L = np.linalg.cholesky(H)
        except np.linalg.LinAlgError:
            return None
        Hinv = np.linalg.inv(H)
        c = Hinv @ bs
        rss = max(rtr - 2.0 * c @ bs + c @ As @ c, 0.0)
        F_ = Hinv @ As
        edf = float(np.trace(F_))
        edf2 = 2.0 * edf - float(np.sum(F_ * F_.T))
        logdet = 2.0 * float(np.sum(np.log(np.diag(L))))
        return c, Hinv, rss, edf, rss + float(c @ Pl @ c), logdet, edf2

    def score(rho: NDArray) -> float:
        out = fit(rho)
        if out is None or out[3] >= R:
            return np.inf
        if criterion == "gcv":
            return math.log(R * max(out[2], 1e-300) / (R - out[3]) ** 2)
        ln10 = math.log(10.0)
        return (R - null) * math.log(max(out[4], 1e-300)) + out[5] - ln10 * float(np.dot(ranks, rho))

    grid = np.arange(LOG_LAMBDA[0], LOG_LAMBDA[1] + 1e-9, 0.5)
    k = len(Ps)
    common = min(grid, key=lambda g: score(np.full(k, g)))
    rho = np.full(k, common)
    if k:
        with np.errstate(invalid="ignore"):  # a step where the score is inf: inf - inf, not a printed warning
            res = scipy.optimize.minimize(score, rho, method="L-BFGS-B", bounds=[LOG_LAMBDA] * k, options={"eps": 1e-4})
        if np.isfinite(res.fun) and score(res.x) <= score(rho):
            rho = res.x
    c, Hinv, rss, edf, _, _, edf2 = fit(rho)
    return PenalisedFit(c / scale, Hinv / np.outer(scale, scale), 10.0**rho, edf, rss, edf2)
