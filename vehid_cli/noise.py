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
