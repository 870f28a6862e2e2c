"""The virtual damper test bench: motion histories of the paper's identification steps, and measured ones.

A history is the prescribed piston motion x(t) [m] (extension positive), its velocity v(t) [m/s], the
control input u(t) [0..1] and, when measured, the force F(t) [N]. Excitations follow Fleps-Dezasse
section 4.2: constant very low velocity in compression and rebound (gas force), a 25 mm sine at 0.8 Hz
(Bouc-Wen or force-map row at one control input), a 25 mm sawtooth at ±0.15 m/s with control steps
(time constants and delays). Measured runs are read by `systems.damper.read_bench` through `io.read.read_record`
(every file format; units through `core.units`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ..core.errors import InputError

BENCH_QUANTITIES = ("time", "displacement", "velocity", "force", "control")  # the columns of a bench file


@dataclass(frozen=True)
class BenchHistory:
    """Prescribed motion and control input on a uniform time grid, with the measured force when known."""

    t: NDArray  # (n,) [s]
    x: NDArray  # (n,) displacement [m]
    v: NDArray  # (n,) velocity [m/s]
    u: NDArray  # (n,) control input [-]
    force: NDArray | None = None  # (n,) measured force [N]
    source: str = "bench"

    @property
    def dt(self) -> float:
        return float(self.t[1] - self.t[0])

    def window(self, start: float, stop: float) -> BenchHistory:
        """The part of the history with start <= t < stop [s] (time kept as is)."""
        keep = (self.t >= start) & (self.t < stop)
        if keep.sum() < 3:
            raise InputError(f"window [{start:g}, {stop:g}) s holds fewer than 3 samples", source=self.source)
        f = None if self.force is None else self.force[keep]
        return replace(self, t=self.t[keep], x=self.x[keep], v=self.v[keep], u=self.u[keep], force=f)


def _grid(duration: float, dt: float) -> NDArray:
    return np.arange(int(round(duration / dt)) + 1) * dt


def _steps(t: NDArray, u0: float, steps: Sequence[tuple[float, float]]) -> NDArray:
    """A control input that starts at u0 and jumps to u at each (time, u) of `steps`."""
    u = np.full(t.size, float(u0))
    for when, value in sorted(steps):
        u[t >= when] = value
    return u


def sine(
    amplitude: float = 0.025, frequency: float = 0.8, cycles: float = 3.0, dt: float = 1e-3, u: float = 0.0
) -> BenchHistory:
    """x = A sin(2 pi f t) at constant control input (the paper's Bouc-Wen step: 25 mm, 0.8 Hz)."""
    t = _grid(cycles / frequency, dt)
    w = 2 * np.pi * frequency
    return BenchHistory(t, amplitude * np.sin(w * t), amplitude * w * np.cos(w * t), np.full(t.size, u), source="sine")


def triangle(
    amplitude: float, velocity: float, cycles: float, dt: float, u0: float, steps: Sequence[tuple[float, float]] = ()
) -> BenchHistory:
    """Constant |velocity| between ±amplitude (a sawtooth of the displacement), starting upwards through 0.

    The reversals are rounded over 2 % of the stroke so that the velocity stays continuous for the integrator.
    """
    period = 4 * amplitude / velocity
    t = _grid(cycles * period, dt)
    phase = (t / period) % 1.0
    x = amplitude * np.where(phase < 0.25, 4 * phase, np.where(phase < 0.75, 2 - 4 * phase, 4 * phase - 4))
    v = np.gradient(x, t)
    # smooth the corners with a short moving average (the test rig's motor cannot reverse instantly)
    k = max(1, int(0.02 * period / dt))
    kernel = np.ones(k) / k
    x = np.convolve(np.pad(x, (k, k), mode="edge"), kernel, mode="same")[k:-k]
    v = np.gradient(x, t)
    return BenchHistory(t, x, v, _steps(t, u0, steps), source="triangle")


def constant_velocity(velocity: float = 0.002, stroke: float = 0.05, u: float = 0.0, dt: float = 1e-3) -> BenchHistory:
    """Very slow motion through the stroke in rebound and back in compression (the gas-force step)."""
    h = triangle(stroke / 2, velocity, 1.0, dt, u)
    return replace(h, source="constant_velocity")


def sawtooth(
    amplitude: float = 0.025,
    velocity: float = 0.15,
    cycles: float = 4.0,
    dt: float = 1e-3,
    u0: float = 0.15,
    steps: Sequence[tuple[float, float]] | None = None,
) -> BenchHistory:
    """±amplitude at constant |velocity| with control steps (default 15 % -> 50 % -> 15 % in rebound and in
    compression: the paper's Figures 11-12, for time constants and delays)."""
    period = 4 * amplitude / velocity
    if steps is None:
        q = period / 4  # steps in the middle of a rebound stroke, then of a compression stroke
        steps = [(0.25 * q, 0.5), (0.75 * q, u0), (1.75 * q, 0.5), (2.25 * q, u0)]
        steps = [(w + period, val) for w, val in steps]  # second cycle: the hysteresis has settled
    h = triangle(amplitude, velocity, cycles, dt, u0, steps)
    return replace(h, source="sawtooth")


def with_force(history: BenchHistory, force: NDArray, source: str | None = None) -> BenchHistory:
    return replace(history, force=np.asarray(force, dtype=float), source=source or history.source)
