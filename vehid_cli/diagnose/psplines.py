"""P-splines: cubic B-spline bases constrained to vanish at 0 with their roughness penalty, and the penalised
least squares with one smoothing parameter per penalised block chosen by REML (or GCV).

* A basis over the range of some values has knots halfway between the values' quantiles and equal spacing
  (dense where the data are, still reaching the sparse extremes); its columns vanish at 0, and its penalty is
  the integrated squared second derivative (exact 2-point Gauss quadrature per knot interval), whose null space,
  the straight line through 0, is free.
* ``penalised_fit`` solves min |r - A c|² + sum_j lambda_j c_j' P_j c_j from the normal equations, each lambda_j
  relative to its block's own scale, and returns the coefficients, their unscaled covariance (A'A + P_lambda)^-1,
  the effective degrees of freedom (the hat matrix' trace) and tr(2 H - H H).
* The B-splines (``bsplines``, Cox-de Boor) and the smoothing parameters' search (``box_minimum``, projected BFGS,
  on REML's exact gradient) are this module's own, not scipy.interpolate's and scipy.optimize's: their imports had
  cost 0.2-0.3 s of `vehid diagnose`'s start-up (tests/test_psplines.py checks both against scipy's).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

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
        return bsplines(xc, self.t) @ self.Z


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
    # penalty: exact 2-point Gauss quadrature per knot interval (B'' is linear on each)
    edges = np.unique(t)
    a, b = edges[:-1], edges[1:]
    g = np.array([-1.0, 1.0]) / math.sqrt(3.0)
    xq = (0.5 * (a + b)[:, None] + 0.5 * (b - a)[:, None] * g[None, :]).ravel()
    wq = np.repeat(0.5 * (b - a), 2)
    d2 = bsplines(xq, t, derivative=2)  # (nq, nb)
    P = d2.T @ (wq[:, None] * d2)
    c = bsplines(np.array([0.0]), t)[0]
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


RIDGE = 1e-9  # added to the scaled normal equations' diagonal: H stays positive definite where a block is unpenalised
LN10 = math.log(10.0)


class _Criterion:
    """The smoothing parameters' criterion on the scaled normal equations As, bs (r'r = rtr, R residuals) with the
    penalties Ps (each lam = 1 on its data's scale, of rank ranks[j]): each fit at rho = log10 lam, its score and
    (REML) its exact gradient. The latest fit is kept: the search asks for its score, then for its gradient."""

    def __init__(self, As: NDArray, bs: NDArray, rtr: float, R: int, Ps: list[NDArray], ranks: list[int],
                 criterion: str) -> None:  # fmt: skip
        self.As, self.bs, self.rtr, self.R, self.Ps, self.ranks = As, bs, rtr, R, Ps, ranks
        self.criterion = criterion
        self.null = As.shape[0] - sum(ranks)  # the penalties' common null space
        self.last: dict[bytes, tuple | None] = {}

    def fit(self, rho: NDArray) -> tuple | None:
        """(c, H^-1, RSS, edf, RSS + c' P_lam c, log|H|, edf2) at rho, None where H is numerically singular."""
        key = rho.tobytes()
        if key not in self.last:
            self.last.clear()
            self.last[key] = self._fit(rho)
        return self.last[key]

    def _fit(self, rho: NDArray) -> tuple | None:
        As, bs, m = self.As, self.bs, self.As.shape[0]
        Pl = sum((10.0**r * P for r, P in zip(rho, self.Ps, strict=True)), np.zeros((m, m)))
        H = As + RIDGE * np.eye(m) + Pl
        try:  # either can refuse an H that is numerically singular: a failed fit, which the search backs away from
            L = np.linalg.cholesky(H)
            Hinv = np.linalg.inv(H)
        except np.linalg.LinAlgError:
            return None
        c = Hinv @ bs
        rss = max(self.rtr - 2.0 * c @ bs + c @ As @ c, 0.0)
        F_ = Hinv @ As
        edf = float(np.trace(F_))
        edf2 = 2.0 * edf - float(np.sum(F_ * F_.T))
        logdet = 2.0 * float(np.sum(np.log(np.diag(L))))
        return c, Hinv, rss, edf, rss + float(c @ Pl @ c), logdet, edf2

    def score(self, rho: NDArray) -> float:
        """REML's (R - M0) log(RSS + c' P_lam c) + log|H| - sum_j rank_j log lam_j, or GCV's log(R RSS / (R - edf)²);
        inf where the fit fails or leaves no degrees of freedom."""
        out, R = self.fit(rho), self.R
        if out is None or out[3] >= R:
            return np.inf
        if self.criterion == "gcv":
            return math.log(R * max(out[2], 1e-300) / (R - out[3]) ** 2)
        return (R - self.null) * math.log(max(out[4], 1e-300)) + out[5] - LN10 * float(np.dot(self.ranks, rho))

    def reml_gradient(self, rho: NDArray) -> NDArray:
        """The REML score's exact gradient: with D = RSS + c' P_lam c and d lam_j / d rho_j = ln10 lam_j,
        dD/d rho_j = ln10 lam_j (c' P_j c + 2 RIDGE c' H^-1 P_j c) (c minimises the penalised sum, ridge included),
        d log|H| / d rho_j = ln10 lam_j tr(H^-1 P_j). NaN where the fit fails (the search stops there)."""
        out = self.fit(rho)
        if out is None or out[3] >= self.R:
            return np.full(rho.size, np.nan)
        c, Hinv, _rss, _edf, D, _logdet, _edf2 = out
        g = np.empty(rho.size)
        for j, P in enumerate(self.Ps):
            lam, Pc = LN10 * 10.0 ** rho[j], P @ c
            dD = lam * (float(c @ Pc) + 2.0 * RIDGE * float(c @ (Hinv @ Pc)))
            g[j] = (self.R - self.null) * dD / max(D, 1e-300) + lam * float(np.sum(Hinv * P)) - LN10 * self.ranks[j]
        return g


def penalised_fit(
    AtA: NDArray,
    Atr: NDArray,
    rtr: float,
    R: int,
    blocks: list[tuple[slice, NDArray]],
    criterion: str = "reml",
) -> PenalisedFit:
    """min |r - A c|² + sum_j lam_j c_j' P_j c_j, the lam_j by REML (default) or GCV, searched from the best common
    value of a grid over LOG_LAMBDA (a start taken from a similar fit instead, e.g. the unexplained force's previous
    trajectory's, stalled where it sat near the upper bound: the score is flat there).

    REML: the restricted likelihood with the scale profiled out, (R - M0) log(RSS + c' P_lam c) + log|H|
    - sum_j rank_j log lam_j, H = A'A + P_lam, M0 the penalty's null-space dimension; GCV: R RSS / (R - edf)².
    """
    scale = np.sqrt(np.maximum(np.diag(AtA), 1e-300))
    As = AtA / np.outer(scale, scale)
    m = As.shape[0]
    Ps, ranks = [], []
    for sl, P in blocks:
        Pj = np.zeros((m, m))
        Pj[sl, sl] = P / np.outer(scale[sl], scale[sl])
        Pj /= max(np.trace(Pj) / (sl.stop - sl.start), 1e-300)  # lam = 1: penalty on the scale of the data term
        ev = np.linalg.eigvalsh(Pj[sl, sl])
        ranks.append(int(np.sum(ev > 1e-9 * ev.max())))
        Ps.append(Pj)
    crit = _Criterion(As, Atr / scale, rtr, R, Ps, ranks, criterion)
    k, score = len(Ps), crit.score
    grid = np.arange(LOG_LAMBDA[0], LOG_LAMBDA[1] + 1e-9, 0.5)
    rho = np.full(k, min(grid, key=lambda g: score(np.full(k, g))))
    if k:
        with np.errstate(invalid="ignore"):  # a step where the score is inf: inf - inf, not a printed warning
            best = box_minimum(score, rho, *LOG_LAMBDA, grad=crit.reml_gradient if criterion == "reml" else None)
        if score(best) <= score(rho):
            rho = best
    c, Hinv, rss, edf, _, _, edf2 = crit.fit(rho)
    return PenalisedFit(c / scale, Hinv / np.outer(scale, scale), 10.0**rho, edf, rss, edf2)


def bsplines(x: NDArray, t: NDArray, degree: int = 3, derivative: int = 0) -> NDArray:
    """(len(x), len(t) - degree - 1): every B-spline of `degree` on the knots t (ends repeated degree + 1 times), or
    its `derivative`, at x within [t[degree], t[-degree - 1]] (the right end in the last interval): the values of
    degree - derivative from those that do not vanish on each x's interval (``_local_values``), then, once per
    derivative, d B_j,p / dx = p (B_j,p-1 / (t_j+p - t_j) - B_j+1,p-1 / (t_j+p+1 - t_j+1)) (0 / 0 = 0). What
    scipy's BSpline.design_matrix and derivative give, to round-off; here to keep scipy.interpolate's import (with
    the scipy it pulls in: 0.2-0.3 s) off `vehid diagnose`'s start-up."""
    x = np.asarray(x, dtype=float)
    t = np.asarray(t, dtype=float)
    nb = t.size - degree - 1
    i = np.clip(np.searchsorted(t, x, side="right") - 1, degree, nb - 1)  # t[i] <= x < t[i + 1]
    B = _local_values(x, t, i, degree - derivative, nb + derivative)  # the values of the lower degree
    for p in range(degree - derivative + 1, degree + 1):  # derivatives of degree p from the p - 1 ones
        j = np.arange(t.size - p - 1)
        B = p * (_ratio(B[:, j], t[j + p] - t[j]) - _ratio(B[:, j + 1], t[j + p + 1] - t[j + 1]))
    return B


def _local_values(x: NDArray, t: NDArray, i: NDArray, degree: int, nb: int) -> NDArray:
    """The values' matrix from the degree + 1 B-splines that do not vanish on each x's interval i (The NURBS Book,
    A2.2: a triangle of ratios per point, its denominators spans of the interval, never 0), scattered into their
    columns (Cox-de Boor's recursion for just these: for many points far cheaper than over every B-spline)."""
    n = x.size
    N = np.zeros((n, degree + 1))
    N[:, 0] = 1.0
    left, right = np.zeros((n, degree + 1)), np.zeros((n, degree + 1))
    for j in range(1, degree + 1):
        left[:, j], right[:, j] = x - t[i + 1 - j], t[i + j] - x
        saved = np.zeros(n)
        for r in range(j):
            temp = N[:, r] / (right[:, r + 1] + left[:, j - r])
            N[:, r] = saved + right[:, r + 1] * temp
            saved = left[:, j - r] * temp
        N[:, j] = saved
    B = np.zeros((n, nb))
    B[np.arange(n)[:, None], (i - degree)[:, None] + np.arange(degree + 1)] = N
    return B


def _ratio(num: NDArray, den: NDArray) -> NDArray:
    """num / den, 0 where den is 0 (a repeated knot: its B-spline of the lower degree vanishes)."""
    safe = np.where(den == 0.0, 1.0, den)
    return np.where(den == 0.0, 0.0, num / safe)


def box_minimum(f, x0: NDArray, lo: float, hi: float, step: float = 1e-4, max_iter: int = 200, grad=None) -> NDArray:
    """A local minimum of the smooth f over the box [lo, hi]^k from x0: projected BFGS on f's gradient `grad(x)` or
    else central differences (step `step`), a backtracking line search along the projected path, the bounds'
    coordinates held while the gradient pushes out; the first step at most 1 long, the inverse Hessian's estimate
    scaled by the first curvature seen (s'y / y'y). Stops when the projected gradient is below 1e-5, a step lowers f by
    less than 1e-12 of it, or none lowers it. scipy's L-BFGS-B, which this replaces to keep scipy.optimize's import off
    the start-up, took forward differences and stopped at a fall of 2.2e-9: on the penalised fits' scores this reaches
    as low in about 1.5x its evaluations; forward differences stalled along a stiff direction. f may be inf where the
    fit fails: the line search backs away from it. An exact gradient (REML's) costs one fit where differences take
    2k: the unexplained force's smoothing searches on a 3 s hysteresis case took a third to a half of their time."""
    gradient = grad or (lambda x: _gradient(f, x, step, lo, hi))
    x = np.clip(np.asarray(x0, dtype=float), lo, hi)
    k = x.size
    fx = f(x)
    g = gradient(x)
    H = None  # the inverse Hessian's estimate, from the first curvature on
    for _ in range(max_iter):
        held = ((x <= lo) & (g > 0)) | ((x >= hi) & (g < 0))
        pg = np.where(held, 0.0, g)
        if not np.all(np.isfinite(g)) or np.max(np.abs(pg), initial=0.0) < 1e-5:
            break
        d = None if H is None else np.where(held, 0.0, -(H @ pg))
        if d is None or d @ g >= 0:  # no estimate yet, or not a descent direction: the projected gradient's
            H, d = None, -pg / max(1.0, float(np.max(np.abs(pg))))
        a, xn, fn = 1.0, x, fx
        while a > 1e-10:
            xn = np.clip(x + a * d, lo, hi)
            fn = f(xn)
            if fn <= fx + 1e-4 * (g @ (xn - x)):
                break
            a *= 0.5
        else:
            break  # no step lowers f
        gn = gradient(xn)
        s, y = xn - x, gn - g
        sy = s @ y
        if sy > 1e-10 * np.linalg.norm(s) * np.linalg.norm(y):  # BFGS update of the inverse Hessian
            H = (sy / (y @ y)) * np.eye(k) if H is None else H
            V = np.eye(k) - np.outer(s, y) / sy
            H = V @ H @ V.T + np.outer(s, s) / sy
        converged = fx - fn <= 1e-12 * max(abs(fx), abs(fn), 1.0)
        x, fx, g = xn, fn, gn
        if converged:
            break
    return x


def _gradient(f, x: NDArray, step: float, lo: float, hi: float) -> NDArray:
    """Central differences of f at x (one-sided at a bound): error O(step²) where forward ones leave O(step) times the
    curvature, which stalled the search along a stiff direction."""
    g = np.empty(x.size)
    for i in range(x.size):
        up, down = x.copy(), x.copy()
        up[i], down[i] = min(x[i] + step, hi), max(x[i] - step, lo)
        g[i] = (f(up) - f(down)) / (up[i] - down[i])
    return g
