"""Road profiles: bump shapes, the rear-axle delay, and the ISO 8608 spectrum."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import signal

from vehid_cli.config import Bump, RandomRoad
from vehid_cli.models.road import ISO_8608_GD_N0, ISO_8608_N0, RandomProfile, bump_road, bump_unit


def test_cosine_step_values():
    s = np.array([-0.01, 0.0, 0.025, 0.05, 0.1, 0.5])
    np.testing.assert_allclose(bump_unit("cosine_step", s, 0.1), [0, 0, (1 - np.cos(np.pi / 4)) / 2, 0.5, 1, 1])


def test_half_sine_and_trapezoid():
    s = np.linspace(-1, 4, 5001)
    half = bump_unit("half_sine", s, 2.0)
    assert half.max() == pytest.approx(1.0) and half[s > 2].max() == 0 and half[s < 0].max() == 0
    assert np.trapezoid(half, s) == pytest.approx(4 / np.pi, rel=1e-5)
    trap = bump_unit("trapezoid", s, 0.5, plateau=1.0)
    assert np.trapezoid(trap, s) == pytest.approx(0.5 + 1.0, rel=1e-5)  # two half ramps + plateau
    assert trap[(s > 0.5) & (s < 1.5)].min() == 1.0 and trap[s > 2.0].max() == 0.0


def test_step_is_sharp():
    np.testing.assert_array_equal(bump_unit("step", np.array([-1e-9, 0.0, 1.0]), 0.1), [0, 1, 1])


def test_rear_tyres_meet_the_bump_wheelbase_over_speed_later():
    V, L = 20 / 3.6, 2.6
    bump = Bump(shape="step", heights=(0.05, 0.04, 0.04, 0.05), start_time=0.1)
    t = np.arange(0, 1.0, 1e-4)
    road = bump_road(bump, V, L, t)
    first = [t[np.argmax(road[:, i] > 0)] for i in range(4)]
    assert first[0] == pytest.approx(0.1, abs=1e-4) and first[1] == pytest.approx(0.1, abs=1e-4)
    assert first[2] == pytest.approx(0.1 + L / V, abs=1e-4) and first[3] == pytest.approx(0.1 + L / V, abs=1e-4)
    np.testing.assert_allclose(road[-1], [0.05, 0.04, 0.04, 0.05])


def test_iso8608_road_has_its_class_spectrum():
    spec = RandomRoad(iso_class="C", n_min=0.05, n_max=4.0, fade_in=0.0)
    profile = RandomProfile(spec, np.random.default_rng(7))
    ds = 0.05
    s = np.arange(0, 4000, ds)
    h = profile.height(0, s)
    gd0 = ISO_8608_GD_N0["C"]
    variance = gd0 * ISO_8608_N0**2 * (1 / spec.n_min - 1 / spec.n_max)  # integral of Gd(n0) (n/n0)^-2
    assert np.var(h) == pytest.approx(variance, rel=0.05)
    n, psd = signal.welch(h, fs=1 / ds, nperseg=8192)
    band = (n > 0.1) & (n < 2.0)
    slope = np.polyfit(np.log(n[band]), np.log(psd[band]), 1)[0]
    assert slope == pytest.approx(-2.0, abs=0.15)
    ref = gd0 * (n[band] / ISO_8608_N0) ** -2
    assert np.median(psd[band] / ref) == pytest.approx(1.0, rel=0.15)


def test_iso8608_tracks_are_independent_and_rear_follows_front():
    spec = RandomRoad(iso_class="B", fade_in=2.0)
    profile = RandomProfile(spec, np.random.default_rng(3))
    V, L = 10.0, 2.6
    t = np.arange(0, 20, 1e-3)
    road = profile.road(V, L, t)
    assert road[0].tolist() == [0, 0, 0, 0]
    lag = int(round(L / V / 1e-3))
    np.testing.assert_allclose(road[lag:, 3], road[:-lag, 0], atol=1e-12)  # corner 4 follows corner 1
    np.testing.assert_allclose(road[lag:, 2], road[:-lag, 1], atol=1e-12)  # corner 3 follows corner 2
    assert abs(np.corrcoef(road[:, 0], road[:, 1])[0, 1]) < 0.3
