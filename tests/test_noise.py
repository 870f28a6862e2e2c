"""Eq. 15 noise: its size per channel, independence, reproducibility."""

from __future__ import annotations

import numpy as np
import pytest

from vehid_cli.models.noise import add_noise, noise_sigma


def test_noise_size_is_level_times_channel_std():
    t = np.linspace(0, 10, 200_000)
    clean = np.column_stack([np.sin(t), 5 * np.cos(3 * t), 0.01 * t])
    noisy = add_noise(clean, 0.2, np.random.default_rng(0))
    measured = (noisy - clean).std(axis=0)
    np.testing.assert_allclose(measured, 0.2 * clean.std(axis=0), rtol=0.01)
    np.testing.assert_allclose(noise_sigma(clean, 0.2), 0.2 * clean.std(axis=0))


def test_channels_are_independent_and_white():
    clean = np.random.default_rng(1).standard_normal((100_000, 4))
    e = add_noise(clean, 0.1, np.random.default_rng(2)) - clean
    corr = np.corrcoef(e.T)
    assert np.abs(corr - np.eye(4)).max() < 0.02
    lag1 = np.mean(e[1:] * e[:-1], axis=0) / e.var(axis=0)
    assert np.abs(lag1).max() < 0.02


def test_same_generator_seed_same_noise_and_zero_level_is_clean():
    clean = np.ones((50, 4)) * np.arange(50)[:, None]
    a = add_noise(clean, 0.1, np.random.default_rng(5))
    b = add_noise(clean, 0.1, np.random.default_rng(5))
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(add_noise(clean, 0.0, np.random.default_rng(5)), clean)
    assert not np.array_equal(a, add_noise(clean, 0.1, np.random.default_rng(6)))


@pytest.mark.parametrize("level", [0.05, 0.1])
def test_noise_is_gaussian(level):
    clean = np.column_stack([np.sin(np.linspace(0, 50, 400_000))])
    z = (add_noise(clean, level, np.random.default_rng(9)) - clean) / noise_sigma(clean, level)
    kurtosis = np.mean(z**4) / np.mean(z**2) ** 2
    assert kurtosis == pytest.approx(3.0, abs=0.05)
