"""diagnose/tails.py: the chi² and F tails against closed forms (chi²(1) = erfc, chi²(2) = exp, F(2, d) a power) and
against scipy.special's chdtrc, chdtri and fdtrc over the degrees of freedom the loop uses and beyond, within each
problem's own condition (a tail's relative error grows with |x - mean| times the round-off of x); and the residuals'
Welch spectrum against scipy.signal's."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import special, stats

from vehid_cli.diagnose.tails import chi2_isf, chi2_sf, f_sf

XS = np.r_[0.0, 1e-12, np.geomspace(1e-6, 2e3, 120)]


def test_closed_forms():
    for x in XS:
        rel = 1e-13 + 1e-16 * x  # the tails' own condition: x's round-off times d ln(sf) / d ln(x) ~ x / 2
        assert chi2_sf(x, 1) == pytest.approx(math.erfc(math.sqrt(x / 2)), rel=rel, abs=1e-300)
        assert chi2_sf(x, 2) == pytest.approx(math.exp(-x / 2), rel=rel, abs=1e-300)
        for d in (3.0, 40.0, 5000.0):
            assert f_sf(x, 2, d) == pytest.approx((d / (d + 2 * x)) ** (d / 2), rel=10 * rel, abs=1e-300)
        # F(1, 1): I_w(1/2, 1/2) = (2 / pi) asin(sqrt(w)); at x = 1e-12 scipy's fdtrc forms 1 - w by subtraction and
        # is 4e-5 off in 1 - sf, these are not
        assert 1 - f_sf(x, 1, 1) == pytest.approx(2 / math.pi * math.asin(math.sqrt(x / (1 + x))), rel=1e-12)
    for p in (0.9, 0.05, 1e-4, 1e-12, 1e-200):
        assert chi2_isf(p, 2) == pytest.approx(-2 * math.log(p), rel=1e-14)


@pytest.mark.parametrize("df", [1, 2, 3, 5, 9, 17, 50, 200])
def test_chi2_as_scipys(df):
    for x in XS:
        ref = special.chdtrc(df, x)
        if ref > 1e-290:
            assert chi2_sf(x, df) == pytest.approx(ref, rel=1e-13 + 1e-16 * x)
    for p in (0.999, 0.5, 0.05, 0.05 / 17, 1e-5, 1e-12, 1e-40):
        x = chi2_isf(p, df)
        assert x == pytest.approx(special.chdtri(df, p), rel=2e-13)
        assert chi2_sf(x, df) == pytest.approx(p, rel=1e-12)  # and it inverts


def test_chi2_with_thousands_of_degrees_of_freedom():
    for df in (1000, 12000):
        for x in np.linspace(0.5 * df, 1.5 * df, 41):
            ref = special.chdtrc(df, x)
            if ref > 1e-290:
                assert chi2_sf(x, df) == pytest.approx(ref, rel=1e-15 * abs(x - df) + 1e-13)
        assert chi2_isf(0.01, df) == pytest.approx(special.chdtri(df, 0.01), rel=1e-13)


@pytest.mark.parametrize("dfn", [1, 2, 3, 5, 10])
def test_f_as_scipys(dfn):
    for dfd in (1, 5, 30, 300, 3000, 30000):
        for x in np.r_[0.0, np.geomspace(1e-6, 1e3, 60)]:
            ref = special.fdtrc(dfn, dfd, x)
            if ref > 1e-290:
                assert f_sf(x, dfn, dfd) == pytest.approx(ref, rel=5e-12)


def same(a: float, b: float) -> bool:
    """Both NaN, or equal to 1e-12 relative."""
    return (math.isnan(a) and math.isnan(b)) or a == pytest.approx(b, rel=1e-12, abs=1e-300)


def test_tails_as_scipy_stats_arguments_included() -> None:
    """scipy.stats, the independent truth they replace: random points, fractional degrees of freedom, and the
    arguments outside the domain (NaN, negative x, p outside [0, 1], df <= 0)."""
    rng = np.random.default_rng(7)
    xs = [*rng.exponential(5.0, 60), 0.0, -1.0, math.inf, math.nan, 1e-12]
    dfs = [0, 1, 2, 3, 6, 1.5, -1]
    for x in xs:
        for k in dfs:
            assert same(chi2_sf(x, k), float(stats.chi2.sf(x, k)))
            for d in (1, 10, 100.5, 0):
                if x != 1e-12:  # where scipy's 1 - w cancels (test_closed_forms)
                    assert same(f_sf(x, k, d), float(stats.f.sf(x, k, d)))
    for p in [*rng.uniform(0.0, 1.0, 30), 0.0, 1.0, 1e-5, -0.1, 1.1]:
        for k in dfs:
            assert same(chi2_isf(p, k), float(stats.chi2.isf(p, k)))


def test_outside_the_domain():
    assert math.isnan(chi2_sf(1.0, 0)) and math.isnan(chi2_sf(math.nan, 3))
    assert chi2_sf(-1.0, 3) == 1.0 and chi2_sf(math.inf, 3) == 0.0
    assert chi2_isf(0.0, 3) == math.inf and chi2_isf(1.0, 3) == 0.0
    assert math.isnan(chi2_isf(1.5, 3)) and math.isnan(chi2_isf(0.5, -1))
    assert math.isnan(f_sf(1.0, 0, 3)) and math.isnan(f_sf(math.nan, 1, 3))
    assert f_sf(-2.0, 1, 3) == 1.0 and f_sf(math.inf, 1, 3) == 0.0


def test_welch_equals_scipy_signal() -> None:
    """diagnose.residuals.welch against scipy.signal.welch's defaults (periodic Hann, half overlap, constant
    detrend, density), on columns and on 1-D signals, segments shorter than, equal to and longer than the signal."""
    import warnings

    from scipy.signal import welch as scipy_welch

    from vehid_cli.diagnose.residuals import welch

    rng = np.random.default_rng(3)
    for n in (7, 255, 256, 257, 1001, 3000):
        for nperseg in (16, 64, 255, 256):
            x = rng.normal(size=(n, 4)) * rng.uniform(0.1, 10.0, 4) + 3.0
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # scipy warns when nperseg > n (and uses n, as welch does)
                f0, p0 = scipy_welch(x, fs=1000.0, nperseg=nperseg, axis=0)
                g0, q0 = scipy_welch(x[:, 1], fs=500.0, nperseg=nperseg)
            f1, p1 = welch(x, 1000.0, nperseg, axis=0)
            g1, q1 = welch(x[:, 1], 500.0, nperseg)
            assert np.array_equal(f0, f1) and np.array_equal(g0, g1)
            np.testing.assert_allclose(p1, p0, rtol=1e-10, atol=0)
            np.testing.assert_allclose(q1, q0, rtol=1e-10, atol=0)


def test_a_long_residuals_spectrum_is_taken_channel_by_channel_to_round_off() -> None:
    """diagnose.residuals.spectrum above SPECTRUM_BATCH_BYTES (a long record's residual) takes one channel's Welch
    segments at a time: the PSD equals the all-channels-at-once welch to round-off (NaN columns on their own grid
    as before); below it, the batched one bit for bit."""
    from vehid_cli.diagnose import residuals
    from vehid_cli.diagnose.residuals import spectrum, welch

    rng = np.random.default_rng(11)
    dt = 1e-3
    for n in (3000, 60000):
        x = rng.normal(size=(n, 8)) * rng.uniform(0.1, 10.0, 8) + 2.0
        x[1::2, 5] = np.nan  # a slow channel on the faster grid
        long = 2 * x.nbytes > residuals.SPECTRUM_BATCH_BYTES
        assert long == (n == 60000)
        f, out = spectrum(x, dt)
        g, p = welch(np.nan_to_num(x), 1.0 / dt, 256, axis=0)
        assert np.array_equal(f, g)
        whole = np.delete(np.arange(8), 5)
        if long:
            np.testing.assert_allclose(out[whole], p.T[whole] / (2 * dt), rtol=1e-12, atol=0)
        else:
            assert np.array_equal(out[whole], p.T[whole] / (2 * dt))
        _, p5 = welch(x[::2, 5], 0.5 / dt, 256)
        expected = np.where(f <= 250.0, np.interp(f, np.fft.rfftfreq(256, 2 * dt), p5 / (4 * dt)), np.nan)
        np.testing.assert_array_equal(out[5], expected)
