"""The loop's chi² and F tail probabilities (diagnose/tails.py, from scipy.special) against scipy.stats, the
independent truth they replace, argument handling included."""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from vehid_cli.diagnose.tails import chi2_isf, chi2_sf, f_sf


def same(a: float, b: float) -> bool:
    return (math.isnan(a) and math.isnan(b)) or a == b


def test_tails_equal_scipy_stats() -> None:
    rng = np.random.default_rng(7)
    xs = [*rng.exponential(5.0, 60), 0.0, -1.0, math.inf, math.nan, 1e-12]
    dfs = [0, 1, 2, 3, 6, 1.5, -1]
    for x in xs:
        for k in dfs:
            assert same(chi2_sf(x, k), float(stats.chi2.sf(x, k)))
            for d in (1, 10, 100.5, 0):
                assert same(f_sf(x, k, d), float(stats.f.sf(x, k, d)))
    for p in [*rng.uniform(0.0, 1.0, 30), 0.0, 1.0, 1e-5, -0.1, 1.1]:
        for k in dfs:
            assert same(chi2_isf(p, k), float(stats.chi2.isf(p, k)))
