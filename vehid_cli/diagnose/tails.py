"""Tail probabilities of the chi² and F distributions for the loop's tests: the regularised incomplete gamma and beta
functions by their series and continued fractions (Numerical Recipes, 3rd ed., 6.2 and 6.4; Lentz's method).

scipy.stats.chi2.sf, .isf and scipy.stats.f.sf compute these (scipy.special's chdtrc, chdtri, fdtrc), but importing
scipy.special (with the scipy._lib it pulls in) cost about 0.2 s of `vehid diagnose`'s start-up on the project's
2-core VM, a tenth of a 3 s case. These agree with scipy's to 1e-13 relative for the degrees of freedom the loop uses
(a few, up to a few hundred) and to 1e-11 for an F test's denominator in the tens of thousands, where the log of the
beta function's prefactor carries the loss (tests/test_tails.py). The argument handling is scipy.stats': NaN outside
the parameters' domain (degrees of freedom <= 0), 1 below the support (x < 0)."""

from __future__ import annotations

import math

TINY = 1e-300  # Lentz's guard against a zero denominator
EPS = 1e-16  # the series' and continued fractions' relative stop
MAX_TERMS = 100_000


def chi2_sf(x: float, df: float) -> float:
    """P(X > x) for X ~ chi²(df) (scipy.stats.chi2.sf(x, df)); NaN when df <= 0 or x is NaN."""
    if not df > 0 or math.isnan(x):
        return math.nan
    return 1.0 if x < 0 else gamma_q(0.5 * df, 0.5 * x)


def chi2_isf(p: float, df: float) -> float:
    """The x with P(X > x) = p for X ~ chi²(df) (scipy.stats.chi2.isf(p, df)); NaN outside 0 <= p <= 1, df > 0."""
    if not (df > 0 and 0.0 <= p <= 1.0):
        return math.nan
    if p == 0.0:
        return math.inf
    if p == 1.0:
        return 0.0
    a = 0.5 * df
    lo, hi = 0.0, max(1.0, 2.0 * df)
    while gamma_q(a, 0.5 * hi) > p:  # bracket the root: Q falls from 1 to 0 as x grows
        lo, hi = hi, 2.0 * hi
    x = min(max(_wilson_hilferty(p, df), lo), hi)
    log_p = math.log(p)
    for _ in range(200):  # Newton on log Q (steep tails stay well scaled), bisection where it would leave the bracket
        q = gamma_q(a, 0.5 * x)
        if q > p:
            lo = x
        else:
            hi = x
        if q <= 0.0 or x <= 0.0:
            new = 0.5 * (lo + hi)
        else:
            hazard = math.exp(_log_gamma_front(a, 0.5 * x) - math.log(x) - math.log(q))  # density / Q
            new = x + (math.log(q) - log_p) / hazard if hazard > 0.0 else 0.5 * (lo + hi)
            if not lo < new < hi:
                new = 0.5 * (lo + hi)
        if abs(new - x) <= 2e-15 * x or hi - lo <= 4 * EPS * hi:
            return new
        x = new
    return x


def f_sf(x: float, dfn: float, dfd: float) -> float:
    """P(X > x) for X ~ F(dfn, dfd) (scipy.stats.f.sf(x, dfn, dfd)); NaN when a dof is <= 0 or x is NaN."""
    if not (dfn > 0 and dfd > 0) or math.isnan(x):
        return math.nan
    if x < 0:
        return 1.0
    if math.isinf(x):
        return 0.0
    total = dfd + dfn * x  # P(F > x) = I_w(dfd / 2, dfn / 2), w = dfd / (dfd + dfn x), 1 - w without cancellation
    return beta_i(dfd / total, dfn * x / total, 0.5 * dfd, 0.5 * dfn)


def gamma_q(a: float, x: float) -> float:
    """The regularised upper incomplete gamma function Q(a, x) = Γ(a, x) / Γ(a), a > 0, x >= 0."""
    if x <= 0.0:
        return 1.0
    if math.isinf(x):
        return 0.0
    log_front = _log_gamma_front(a, x)
    if x < a + 1.0:  # the series of P converges fast here: Q = 1 - P
        term = total = 1.0 / a
        ap = a
        for _ in range(MAX_TERMS):
            ap += 1.0
            term *= x / ap
            total += term
            if abs(term) < abs(total) * EPS:
                break
        return max(0.0, 1.0 - total * math.exp(log_front))
    b = x + 1.0 - a  # the continued fraction of Q (modified Lentz)
    c, d = 1.0 / TINY, 1.0 / b
    h = d
    for i in range(1, MAX_TERMS):
        an = -i * (i - a)
        b += 2.0
        d = an * d + b
        d = TINY if abs(d) < TINY else d
        c = b + an / c
        c = TINY if abs(c) < TINY else c
        d = 1.0 / d
        delta = d * c
        h *= delta
        if abs(delta - 1.0) < EPS:
            break
    return math.exp(log_front) * h


def beta_i(w: float, w1: float, a: float, b: float) -> float:
    """The regularised incomplete beta function I_w(a, b), a, b > 0, given w and w1 = 1 - w (each computed without
    cancellation by the caller)."""
    if w <= 0.0:
        return 0.0
    if w1 <= 0.0:
        return 1.0
    log_w = math.log1p(-w1) if w1 < 0.5 else math.log(w)
    log_w1 = math.log1p(-w) if w < 0.5 else math.log(w1)
    log_front = a * log_w + b * log_w1 - _log_beta(a, b)
    if w < (a + 1.0) / (a + b + 2.0):  # the continued fraction converges fast on this side; else by symmetry
        return math.exp(log_front) * _beta_fraction(w, a, b) / a
    return 1.0 - math.exp(log_front) * _beta_fraction(w1, b, a) / b


def _beta_fraction(w: float, a: float, b: float) -> float:
    """The continued fraction of the incomplete beta function (modified Lentz)."""
    qab, qap, qam = a + b, a + 1.0, a - 1.0
    c, d = 1.0, 1.0 - qab * w / qap
    d = 1.0 / (TINY if abs(d) < TINY else d)
    h = d
    for m in range(1, MAX_TERMS):
        m2 = 2 * m
        for aa in (m * (b - m) * w / ((qam + m2) * (a + m2)), -(a + m) * (qab + m) * w / ((a + m2) * (qap + m2))):
            d = 1.0 + aa * d
            d = 1.0 / (TINY if abs(d) < TINY else d)
            c = 1.0 + aa / c
            c = TINY if abs(c) < TINY else c
            delta = d * c
            h *= delta
        if abs(delta - 1.0) < EPS:
            break
    return h


def _stirling_error(z: float) -> float:
    """lgamma(z) - ((z - 1/2) ln z - z + ln(2 pi) / 2), the remainder of Stirling's formula, without cancellation for
    large z (its asymptotic series, to 1e-17 for z >= 10)."""
    if z < 10.0:
        return math.lgamma(z) - ((z - 0.5) * math.log(z) - z + 0.5 * math.log(2.0 * math.pi))
    r = 1.0 / (z * z)
    return (1.0 / 12 - r * (1.0 / 360 - r * (1.0 / 1260 - r * (1.0 / 1680 - r / 1188)))) / z


def _log_gamma_front(a: float, x: float) -> float:
    """ln(x^a e^-x / Γ(a)): for large a from Stirling's formula, its large terms cancelled by hand (a ln(x / a) -
    (x - a) = a (log1p(d) - d), d = (x - a) / a): lgamma(a) alone would carry an error of eps * a ln a."""
    if a < 10.0:
        return a * math.log(x) - x - math.lgamma(a)
    d = (x - a) / a
    return a * (math.log1p(d) - d) + 0.5 * math.log(a / (2.0 * math.pi)) - _stirling_error(a)


def _log_beta(a: float, b: float) -> float:
    """ln B(a, b); for a large part lgamma(a + b) - lgamma(a) = (a - 1/2) log1p(b / a) + b ln(a + b) - b + the
    Stirling remainders (not the difference of two large logs), and the same with a and b swapped."""
    if a < b:
        a, b = b, a
    if a < 10.0:
        return math.lgamma(a) + math.lgamma(b) - math.lgamma(a + b)
    rise = (a - 0.5) * math.log1p(b / a) + b * math.log(a + b) - b + _stirling_error(a + b) - _stirling_error(a)
    return math.lgamma(b) - rise


def _wilson_hilferty(p: float, df: float) -> float:
    """Wilson and Hilferty's approximation of chi2_isf(p, df): a start for Newton's iteration."""
    z = _normal_isf(p)
    k = 2.0 / (9.0 * df)
    return max(df * (1.0 - k + z * math.sqrt(k)) ** 3, 1e-300)


def _normal_isf(p: float) -> float:
    """The standard normal's upper p-quantile to about 4.5e-4 (Abramowitz and Stegun 26.2.23): a start only."""
    q = min(p, 1.0 - p)
    t = math.sqrt(-2.0 * math.log(max(q, 1e-300)))
    z = t - (2.515517 + 0.802853 * t + 0.010328 * t * t) / (1.0 + 1.432788 * t + 0.189269 * t * t + 0.001308 * t**3)
    return z if p < 0.5 else -z
