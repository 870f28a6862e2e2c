"""Road inputs under the four tyres: bump shapes met at constant speed, ISO 8608 random roads.

Every profile is a pure function of time, so it can be sampled on any grid (the simulation grid, or a
much finer one for a converged reference). The rear tyres travel the same track as the front tyres of
their side, (a1 + a2)/V later.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike, NDArray


class Bump(Protocol):
    """A discrete obstacle (the config's `road.bump`): shape, length [m], plateau [m], heights under corners 1..4 [m],
    the time the front tyres meet it [s]."""

    shape: str
    length: float
    plateau: float
    heights: tuple[float, float, float, float]
    start_time: float


class RandomRoad(Protocol):
    """An ISO 8608 random road (the config's `road.random`): class, band of spatial frequencies [cycles/m], fade-in
    distance [m]."""

    iso_class: str
    n_min: float
    n_max: float
    fade_in: float


class Road(Protocol):
    """The configured road (the config's `road`): bumps and/or a random road at the forward speed V [m/s]."""

    file: str | None
    bump: Bump | None
    random: RandomRoad | None

    @property
    def V(self) -> float: ...


REAR_CORNERS = np.array([False, False, True, True])  # corners 3, 4
SIDE_OF_CORNER = np.array([0, 1, 1, 0])  # wheel track: 0 = side b1 (corners 1, 4), 1 = side b2 (2, 3)
ISO_8608_GD_N0 = {c: 16e-6 * 4**i for i, c in enumerate("ABCDEFGH")}  # m³, class geometric mean at n0
ISO_8608_N0 = 0.1  # reference spatial frequency [cycles/m]


def bump_unit(shape: str, s: ArrayLike, length: float, plateau: float = 0.0) -> NDArray:
    """Unit-height bump profile at distance s [m] past its start (zero before it)."""
    s = np.asarray(s, dtype=float)
    x = np.clip(s / length, 0.0, 1.0)
    if shape == "step":
        return (s >= 0).astype(float)
    if shape == "cosine_step":
        return np.where(s > 0, 0.5 * (1.0 - np.cos(np.pi * x)), 0.0)
    if shape == "half_sine":
        return np.where((s > 0) & (s < length), np.sin(np.pi * x), 0.0)
    if shape == "trapezoid":
        up = np.clip(s / length, 0.0, 1.0)
        down = np.clip((2 * length + plateau - s) / length, 0.0, 1.0)
        return np.minimum(up, down)
    raise ValueError(f"unknown bump shape {shape!r}")


def corner_delays(wheelbase: float, speed: float) -> NDArray:
    """Delay [s] with which each tyre meets a feature the front tyres meet at t = 0."""
    return np.where(REAR_CORNERS, wheelbase / speed, 0.0)


def bump_road(bump: Bump, speed: float, wheelbase: float, t: ArrayLike) -> NDArray:
    """Road heights (n, 4) [m] at times t [s] for a bump met by the front tyres at bump.start_time."""
    t = np.asarray(t, dtype=float)
    s = speed * (t[:, None] - bump.start_time - corner_delays(wheelbase, speed)[None, :])
    return bump_unit(bump.shape, s, bump.length, bump.plateau) * np.asarray(bump.heights)[None, :]


class RandomProfile:
    """An ISO 8608 random road as a sum of cosines: evaluable at any distance, drawn once from `rng`.

    The displacement PSD is Gd(n) = Gd(n0) (n / n0)^-2 between n_min and n_max; each wheel track gets
    its own independent profile, faded in from zero over `fade_in` metres so the car starts at rest.
    """

    def __init__(self, spec: RandomRoad, rng: np.random.Generator, n_waves: int = 2000):
        self.spec = spec
        self.n = np.linspace(spec.n_min, spec.n_max, n_waves)
        dn = self.n[1] - self.n[0]
        gd = ISO_8608_GD_N0[spec.iso_class] * (self.n / ISO_8608_N0) ** -2.0
        self.amplitude = np.sqrt(2.0 * gd * dn)  # one-sided PSD -> cosine amplitudes
        self.phase = rng.uniform(0.0, 2.0 * np.pi, size=(2, n_waves))

    def height(self, side: int, s: ArrayLike, chunk: int = 512) -> NDArray:
        """Height [m] of wheel track `side` (0 = b1, 1 = b2) at distances s [m]."""
        s = np.asarray(s, dtype=float)
        out = np.empty(s.shape)
        flat_s, flat_out = s.reshape(-1), out.reshape(-1)
        for i in range(0, flat_s.size, chunk):
            block = flat_s[i : i + chunk]
            flat_out[i : i + chunk] = (
                np.cos(2 * np.pi * self.n[None, :] * block[:, None] + self.phase[side][None, :]) @ self.amplitude
            )
        fade = self.spec.fade_in
        window = np.clip(s / fade, 0.0, 1.0) if fade > 0 else (s >= 0).astype(float)
        return out * 0.5 * (1.0 - np.cos(np.pi * window))

    def road(self, speed: float, wheelbase: float, t: ArrayLike) -> NDArray:
        """Road heights (n, 4) [m] at times t [s]; the front tyres start the track at t = 0."""
        t = np.asarray(t, dtype=float)
        out = np.empty((t.size, 4))
        for corner in range(4):
            s = speed * (t - corner_delays(wheelbase, speed)[corner])
            out[:, corner] = self.height(SIDE_OF_CORNER[corner], s)
        return out


def road_function(road: Road, wheelbase: float, rng: np.random.Generator | None = None):
    """The configured road (bumps plus random roughness) as a function t -> (n, 4) heights [m]."""
    if road.file is not None:
        raise ValueError("a road from a file is sampled data, not a function of time")
    speed = road.V
    profile = None
    if road.random is not None:
        if rng is None:
            raise ValueError("a random road needs a random generator")
        profile = RandomProfile(road.random, rng)

    def heights(t: ArrayLike) -> NDArray:
        t = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.zeros((t.size, 4))
        if road.bump is not None:
            out += bump_road(road.bump, speed, wheelbase, t)
        if profile is not None:
            out += profile.road(speed, wheelbase, t)
        return out

    return heights


def chirp(t: ArrayLike, f0: float, f1: float, amplitude: float, start: float, duration: float, fade: float) -> NDArray:
    """A linear sine sweep (a rig's road plate or actuator): amplitude sin(2 pi (f0 s + (f1 - f0) s² / (2 T))) for
    s = t - start in [0, T], T = duration, zero outside; faded in and out by a half cosine over `fade` seconds, so
    that the rig starts and ends at rest."""
    s = np.asarray(t, dtype=float) - start
    inside = (s >= 0) & (s <= duration)
    phase = 2 * np.pi * (f0 * s + (f1 - f0) * s**2 / (2 * duration))
    ramp = np.clip(np.minimum(s, duration - s) / fade, 0.0, 1.0) if fade > 0 else np.ones_like(s)
    return np.where(inside, amplitude * np.sin(phase) * 0.5 * (1 - np.cos(np.pi * ramp)), 0.0)
