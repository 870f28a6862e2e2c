"""Measurement noise of Gökdağ Eq. 15: z_r = z_c + std(z_c) * Np * randn, independent per channel."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray


def noise_sigma(clean: NDArray, level: float) -> NDArray:
    """Noise standard deviation per channel (..., k) for clean signals (..., n, k): level * std over time."""
    return level * np.std(clean, axis=-2)


def add_noise(clean: NDArray, level: float, rng: np.random.Generator) -> NDArray:
    """Noisy copy of clean (..., n, k): white Gaussian noise, sigma_i = level * std(clean_i) (Eq. 15)."""
    clean = np.asarray(clean, dtype=float)
    if level == 0:
        return clean.copy()
    sigma = noise_sigma(clean, level)
    return clean + sigma[..., None, :] * rng.standard_normal(clean.shape)


def estimate_noise_sigma(measured: NDArray) -> NDArray:
    """Noise standard deviation per channel (..., k) estimated from the data (..., n, k) alone.

    White noise dominates the third difference of a signal sampled far faster than its dynamics:
    var(Δ³e) = 20 σ² (binomial coefficients 1, 3, 3, 1). A median-absolute-deviation estimate of the
    third differences keeps the few samples where the signal itself changes fast (a bump) from biasing it.
    """
    measured = np.asarray(measured, dtype=float)
    d3 = np.diff(measured, n=3, axis=-2)
    mad = np.median(np.abs(d3 - np.median(d3, axis=-2, keepdims=True)), axis=-2)
    return mad / 0.6744897501960817 / np.sqrt(20.0)


def sigma_from_level(measured: NDArray, level: float) -> NDArray:
    """Eq. 15 noise sigma per channel when only noisy data is at hand: var(noisy) = (1 + level²) var(clean)."""
    return level * np.std(np.asarray(measured, dtype=float), axis=-2) / np.sqrt(1.0 + level**2)


def with_floors(sigma: NDArray, floors: NDArray | None) -> NDArray:
    """Noise standard deviation per channel (k,): a channel's absolute floor where `floors` gives one (not NaN), else
    `sigma`."""
    if floors is None:
        return sigma
    floors = np.asarray(floors, dtype=float)
    return np.where(np.isnan(floors), sigma, floors)


def channel_sigma(clean: NDArray, level: float, floors: NDArray | None = None) -> NDArray:
    """Noise standard deviation per channel (k,) of clean signals (n, k): a channel's absolute floor where `floors`
    gives one (not NaN), else Eq. 15 (level * std over time)."""
    return with_floors(noise_sigma(clean, level), floors)


def per_channel(statistic, values: NDArray, observed: NDArray | None) -> NDArray:
    """A per-channel statistic (k,) of values (n, k) (`statistic` maps (m, k) to (k,), e.g. estimate_noise_sigma),
    each channel over its own samples only (`observed`: (n, k) bool; None: every sample)."""
    if observed is None:
        return statistic(values)
    return np.array([float(statistic(values[observed[:, c], c][:, None])[0]) for c in range(values.shape[1])])


def add_channel_noise(clean: NDArray, sigma: NDArray, rng: np.random.Generator) -> NDArray:
    """Noisy copy of clean (n, k): white Gaussian noise of standard deviation sigma (k,) per channel; nothing is
    drawn from `rng` when every sigma is 0 (as `add_noise` at level 0)."""
    clean = np.asarray(clean, dtype=float)
    sigma = np.asarray(sigma, dtype=float)
    if not np.any(sigma > 0):
        return clean.copy()
    return clean + sigma[..., None, :] * rng.standard_normal(clean.shape)
