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
