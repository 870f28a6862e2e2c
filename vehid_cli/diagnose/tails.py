"""Tail probabilities of the chi² and F distributions for the loop's tests, from scipy.special.

scipy.stats.chi2.sf, .isf and scipy.stats.f.sf compute exactly these (scipy.special's chdtrc, chdtri, fdtrc) after
checking their arguments; importing scipy.stats costs about 0.35 s of `vehid diagnose`'s start-up on the project's
2-core VM (0.2 s of it its docstring machinery), which a 3 s case cannot afford. The argument handling is the same:
NaN outside the parameters' domain (degrees of freedom <= 0), 1 below the support (x < 0)."""

from __future__ import annotations

import math

from scipy import special


def chi2_sf(x: float, df: float) -> float:
    """P(X > x) for X ~ chi²(df) (scipy.stats.chi2.sf(x, df)); NaN when df <= 0 or x is NaN."""
    if not df > 0 or math.isnan(x):
        return math.nan
    return 1.0 if x < 0 else float(special.chdtrc(df, x))


def chi2_isf(p: float, df: float) -> float:
    """The x with P(X > x) = p for X ~ chi²(df) (scipy.stats.chi2.isf(p, df)); NaN outside 0 <= p <= 1, df > 0."""
    if not (df > 0 and 0.0 <= p <= 1.0):
        return math.nan
    return float(special.chdtri(df, p))


def f_sf(x: float, dfn: float, dfd: float) -> float:
    """P(X > x) for X ~ F(dfn, dfd) (scipy.stats.f.sf(x, dfn, dfd)); NaN when a dof is <= 0 or x is NaN."""
    if not (dfn > 0 and dfd > 0) or math.isnan(x):
        return math.nan
    return 1.0 if x < 0 else float(special.fdtrc(dfn, dfd, x))
