"""Measurement noise: Gökdağ Eq. 15 (z_r = z_c + std(z_c) * Np * randn, independent per channel), absolute floors
per channel, estimates from the data; `NoiseModel` is a config's noise resolved once."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

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


MIN_SIGMA_FRACTION = 1e-3  # noise-free data: weight channels as if Np were 0.1 %, to keep wls finite


@dataclass(frozen=True)
class NoiseModel:
    """The measurement noise a config declares, resolved once: Eq. 15's level Np and each channel's absolute floor
    per family (the sensor's own sigma, else its family's noise.sigma; NaN: none, Eq. 15 applies). Every sigma the
    package uses comes from one of its three methods."""

    level: float
    floors: Mapping[str, NDArray] = field(default_factory=dict)  # family -> (k,) [SI], NaN where none

    def floor(self, family: str) -> NDArray | None:
        return self.floors.get(family)

    def has_floors(self, families: tuple[str, ...]) -> bool:
        """Does any channel of these families have an absolute floor?"""
        return any(np.any(~np.isnan(self.floors[f])) for f in families if f in self.floors)

    def drawn(self, family: str, clean: NDArray) -> NDArray:
        """The sigma (k,) simulated noise is drawn with for clean channels (n, k): the floor, else Eq. 15 (level x the
        clean channel's standard deviation over time)."""
        return channel_sigma(clean, self.level, self.floor(family))

    def weights(self, family: str, clean: NDArray) -> NDArray:
        """The sigma (k,) that weights simulated data in wls and the bound: as `drawn`, but never below Eq. 15 at
        MIN_SIGMA_FRACTION (noise-free data keeps finite weights)."""
        return channel_sigma(clean, max(self.level, MIN_SIGMA_FRACTION), self.floor(family))

    def estimated(self, family: str, measured: NDArray, observed: NDArray | None = None) -> NDArray:
        """The sigma (k,) of measured channels (n, k), each over its own samples (`observed`): the floor, else Eq. 15
        from the noisy data when a level is declared, else estimated from the data (third differences)."""
        statistic = (lambda y: sigma_from_level(y, self.level)) if self.level > 0 else estimate_noise_sigma
        return with_floors(per_channel(statistic, measured, observed), self.floor(family))

    def describe_simulated(self, families: tuple[str, ...]) -> str:
        """Where simulated data's weights come from, in words (results' `sigma_source`)."""
        level, floor = self.level, max(self.level, MIN_SIGMA_FRACTION)
        source = f"Eq. 15 with Np = {level:g}" if level > 0 else f"noise-free data: weights of Np = {floor:g}"
        if self.has_floors(families):
            source = "the configured noise floors" + (f" and Eq. 15 with Np = {level:g}" if level > 0 else "")
        return source

    def describe_measured(self, families: tuple[str, ...]) -> str:
        """Where measured data's sigma comes from, in words (results' `sigma_source`)."""
        if self.level > 0:
            source = f"Eq. 15 with Np = {self.level:g} (noise.level)"
        else:
            source = "estimated from the data (third differences)"
        if self.has_floors(families):
            source = f"the configured noise floors, elsewhere {source}"
        return source
