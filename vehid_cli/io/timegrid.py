"""One uniform time grid for the channels of a logger file: their time stamps checked, their rates, the grid, and
each channel put on it (`io.read.read_record` runs these steps in order; `Record.native_samples` asks
`native_samples`).

- the grid rate is `rate` when given, else the highest channel rate; the grid spans the time all channels cover;
- a channel sampled faster than the grid (down-sampling) is first low-passed on its own grid with a zero-phase
  Butterworth filter (order 8, `scipy.signal.sosfiltfilt`, cut-off at 40 % of the grid rate, i.e. 80 % of the new
  Nyquist frequency), then interpolated: content above the new Nyquist frequency is removed, not folded back;
- a channel sampled at the grid rate or slower (up-sampling) is interpolated with a cubic spline (not-a-knot);
  samples already on the grid are kept as they are;
- the low-pass starts up over about 2.5 / cut-off seconds at the record's ends (30 ms for a 200 Hz grid): there,
  content above the new Nyquist frequency is not fully removed; cut it with `window` when it matters;
- time stamps that jitter are resampled the same way: steps within ±50 % of the median step at the median rate;
  stamps that jitter more (a lab rig's clock: each stamp anywhere within about half a step of its slot, so that
  steps run from near 0 to near 2 steps) are told from gaps by their slots on the uniform grid fitted to them (least
  squares over the sample index): jitter scatters the stamps about their slots, a dropped block of samples moves
  every later stamp off its slot by the block's length, which the means of the deviation over adjacent windows show
  as a shift of more than half a step (`GRID_SHIFT`), or a stamp further than ¾ step from its slot (`GRID_SLOT`: a block
  dropped near an end); such a record is resampled at the fitted rate. A gap is an error, as is a time
  that goes backwards.

`resample=False` refuses all of this: channels at different rates, jittered stamps or samples off the common grid
are an error, and every value in the Record is a sample of the file. Either way the Record keeps each channel's
own rate and sample times (`Record.rates`, `Record.stamps`), and `Record.native_samples` gives the grid points
that hold a channel's own samples (a 200 Hz channel on a 1 kHz grid: every 5th).
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from numpy.typing import NDArray

from ..core.errors import InputError
from .formats.base import Raw
from .measurement import UNIFORM_TOLERANCE

JITTER = 0.5  # a step within ±50 % of the median step is jitter (resampled); beyond, the grid's slots judge
GRID_SHIFT = 0.5  # ... the stamps' deviation from the fitted grid shifting by more steps between windows: a gap
GRID_WINDOW = 101  # samples in each such window (at most a quarter of the record)
GRID_SLOT = 0.75  # ... or a stamp further than this many steps from its slot so moved (½ step of jitter, the slot's
# uncertainty, and short of the whole step a block dropped near an end moves it)
DOWNSAMPLE_ORDER = 8  # Butterworth order of the anti-alias filter (applied forwards and backwards: zero phase)
DOWNSAMPLE_CUTOFF = 0.4  # its cut-off as a fraction of the new rate (0.8 x the new Nyquist frequency)
RATE_MATCH = 1e-2  # a channel within 1 % of the grid rate is at the grid rate (no filter)
NOMINAL_RATE_MATCH = 0.05  # time stamps printed off a nominal rate: each step within 5 % of 1 / rate
NATIVE_MATCH = 1e-3  # a channel's sample within 1e-3 of a grid step of a grid point is on that grid point
LARGEST = 1e12  # |value| [SI] beyond which a sample or time stamp is no measurement (1e12 s, m, m/s², N)
UPSAMPLE_LIMIT = 100.0  # a grid rate at most this many times the fastest channel's rate
GRID_BUDGET = 2 << 30  # bytes the grid's channels may take (GRID_COPIES working copies of each)
GRID_COPIES = 4  # the values, the spline's coefficients and the record's copies
RESAMPLE_HINT = "allow resampling to read it (resample=True; config key data.resample)"


class NominalRateError(InputError):
    """Time stamps that do not follow the nominal rate given to `read_record` (callers may name their key)."""


def _named(time: str, before: str = "") -> str:
    """ " '<time column>'" (after `before`) when the stamps come from a named column/vector, else ''."""
    return f"{before} '{time}'" if time else ""


def _worst_step(steps: NDArray, dt: float) -> int:
    """The index of the time step furthest from dt [s]: what the nominal-rate check (5 %) and the gap check (50 %)
    each judge against their own tolerance."""
    return int(np.argmax(np.abs(steps - dt)))


# ------------------------------------------------------------------------------------------ time stamps


def on_nominal_rate(name: str, theirs: str, raw: Raw, rate: float, src: str) -> None:
    """Printed time stamps rounded off a nominal rate: check every step is within 5 % of 1 / rate, then rebuild
    the stamps as t0 + k / rate (the samples are kept as they are, not resampled)."""
    dt = 1.0 / rate
    steps = np.diff(raw.t)
    bad = _worst_step(steps, dt)
    if abs(steps[bad] - dt) > NOMINAL_RATE_MATCH * dt:
        raise NominalRateError(
            f"channel '{name}' ('{theirs}'): time{_named(raw.time)} does not follow the nominal rate {rate:g} Hz "
            f"(step {dt:g} s) within {NOMINAL_RATE_MATCH:.0%}: step {steps[bad]:g} s at sample {bad + 2}",
            source=src,
        )
    raw.t = raw.t[0] + np.arange(raw.t.size) * dt


def check_channel(name: str, theirs: str, raw: Raw, src: str) -> float:
    """Check a channel's stamps and values; return its (median) sampling step [s]."""
    label = f"channel '{name}' ('{theirs}')"
    if raw.t.size != raw.y.size:
        raise InputError(f"{label} has {raw.y.size} samples but its time vector {raw.t.size}", source=src)
    if raw.y.size < 3:
        raise InputError(f"{label} has {raw.y.size} samples; at least 3 are needed", source=src)
    for what, values in (("time stamp", raw.t), ("sample", raw.y)):
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            raise InputError(
                f"{label} has {bad.size} non-finite {what}(s){_named(raw.time, ' in') if what[0] == 't' else ''} "
                f"(NaN or Inf), first at sample {bad[0] + 1}",
                source=src,
            )
        huge = np.flatnonzero(np.abs(values) > LARGEST)
        if huge.size:
            raise InputError(
                f"{label} has {huge.size} {what}(s){_named(raw.time, ' in') if what[0] == 't' else ''} beyond "
                f"±{LARGEST:g} (SI units), first at sample {huge[0] + 1}: {values[huge[0]]:.6g}; a damaged file or a "
                f"wrong unit",
                source=src,
            )
    steps = np.diff(raw.t)
    if np.any(steps <= 0):
        k = int(np.flatnonzero(steps <= 0)[0])
        raise InputError(
            f"{label}: time{_named(raw.time)} goes backwards (or stands still), it must increase strictly: at "
            f"sample {k + 2}, t = {raw.t[k + 1]:.9g} s after {raw.t[k]:.9g} s",
            source=src,
        )
    dt = float(np.median(steps))
    worst = _worst_step(steps, dt)
    if abs(steps[worst] - dt) <= JITTER * dt:
        return dt
    fitted, shift, off = grid_shift(raw.t)
    if shift > 1.0 or off > GRID_SLOT:
        raise InputError(
            f"{label}: a gap in time at sample {worst + 2}: step {steps[worst]:.6g} s against the usual {dt:.6g} s, "
            f"and the stamps leave their slots on a uniform grid by up to {max(shift * GRID_SHIFT, off):.2g} steps "
            f"(dropped samples?); cut the record with a window",
            source=src,
        )
    return fitted


def grid_shift(t: NDArray) -> tuple[float, float, float]:
    """The step [s] of the uniform grid fitted to stamps `t` (least squares over the sample index) and two measures
    of how the stamps leave their slots on it. A dropped block of samples moves every later stamp off its slot by the
    block's length, jitter scatters them about their slots: (1) the largest shift [steps] of the deviation between
    the means of two adjacent windows (2, 5, 11, ... `GRID_WINDOW` samples each, at most a quarter of the record),
    over the shift the jitter alone could make at that window (`GRID_SHIFT` steps or 6 sd of the difference of two
    such means, the jitter's sd from the stamps); (2) the largest distance [steps] of a stamp from the mean of its
    largest window (a block dropped within a window of an end moves only the last few stamps)."""
    index = np.arange(t.size, dtype=float)
    step, start = np.polyfit(index, t - t[0], 1)
    deviation = (t - t[0] - start - step * index) / step
    moves = np.diff(deviation)
    sd = 1.4826 * float(np.median(np.abs(moves - np.median(moves)))) / math.sqrt(2)  # robust: a gap is one move
    ratio, window, level = 0.0, 2, deviation
    while window <= max(2, min(GRID_WINDOW, t.size // 4)):
        level = np.convolve(deviation, np.full(window, 1.0 / window), mode="valid")
        if level.size > window:
            noise = max(GRID_SHIFT, 6.0 * sd * math.sqrt(2.0 / window))
            ratio = max(ratio, float(np.max(np.abs(level[window:] - level[:-window]))) / noise)
        window, last = 2 * window + 1, window
    level = np.pad(level, (last // 2, last - 1 - last // 2), mode="edge")  # the ends' slots as their window's
    return float(step), ratio, float(np.max(np.abs(deviation - level)))


def uniform(t: NDArray, dt: float) -> bool:
    """Are the stamps `t` uniform at step dt [s] (to `measurement.UNIFORM_TOLERANCE`, or round-off of their size)?"""
    return bool(np.max(np.abs(np.diff(t) - dt)) <= max(UNIFORM_TOLERANCE * dt, 1e-9 * float(np.max(np.abs(t)))))


def rate_of(raw: Raw, dt: float) -> float:
    """A channel's rate [Hz]: from its span when uniform, else its median step; to 9 significant digits (a logger's
    nominal rate, not the round-off of its time stamps: 1/0.0010000000000000002 s is 1000 Hz)."""
    rate = (raw.t.size - 1) / float(raw.t[-1] - raw.t[0]) if uniform(raw.t, dt) else 1.0 / dt
    return float(f"{rate:.9g}")


# ------------------------------------------------------------------------------------------ the grid


def common_grid(
    raw: Mapping[str, Raw], channels: Mapping[str, str], rates: Mapping[str, float], rate: float | None, src: str
) -> tuple[NDArray, float, float]:
    """The grid [s, on the file's axis], its rate [Hz] (`rate`, else the highest channel rate) and its start (the
    latest first stamp): over the time all channels cover; InputError when that is less than 3 samples, or more
    than memory and the channels' rates justify (`check_grid_size`)."""
    grid_rate = rate if rate is not None else max(rates.values())
    start = max(float(r.t[0]) for r in raw.values())
    stop = min(float(r.t[-1]) for r in raw.values())
    samples = (stop - start) * grid_rate  # a float first: a hostile rate or span must not reach an allocation
    if not stop > start or not samples >= 2 - 1e-6:
        raise InputError(
            f"the channels ({', '.join(channels)}) share no common time span of 3 samples at {grid_rate:g} Hz",
            source=src,
        )
    check_grid_size(samples + 1, grid_rate, stop - start, len(raw), max(rates.values()), src)
    n = int(math.floor(samples + 1e-6)) + 1  # 1e-6: a sample at `stop` despite round-off
    return start + np.arange(n) / grid_rate, grid_rate, start


def check_grid_size(n: float, grid_rate: float, span: float, channels: int, fastest: float, src: str) -> None:
    """A grid of `n` samples at `grid_rate` [Hz] over `span` [s] for `channels` channels (the fastest sampled at
    `fastest` Hz): InputError when it up-samples beyond UPSAMPLE_LIMIT x the fastest channel (interpolated
    samples carry nothing, and every later step pays for them), or needs more than GRID_BUDGET bytes."""
    needed = n * (channels + 1) * 8.0 * GRID_COPIES
    if grid_rate > UPSAMPLE_LIMIT * fastest * (1 + RATE_MATCH) or needed > GRID_BUDGET:
        raise InputError(
            f"a grid at {grid_rate:g} Hz over the record's {span:.6g} s is {n:.6g} samples for {channels} channels "
            f"(about {needed / 2**30:.3g} GiB); the fastest channel is sampled at {fastest:g} Hz: the grid rate may "
            f"be at most {UPSAMPLE_LIMIT:g} times that, and the grid at most {GRID_BUDGET / 2**30:g} GiB; give a "
            f"lower rate (data.rate) or a shorter window",
            source=src,
        )


def _grid_slice(raw: Raw, dt: float, grid: NDArray) -> slice | None:
    """The run of the channel's samples that lies on the grid (each stamp within UNIFORM_TOLERANCE of a step of
    its grid point), None if there is none: the channel is then resampled."""
    first = int(round((grid[0] - raw.t[0]) / dt))
    keep = slice(first, first + grid.size)
    if first < 0 or keep.stop > raw.t.size:
        return None
    return keep if np.allclose(raw.t[keep], grid, rtol=0, atol=UNIFORM_TOLERANCE * dt) else None


def onto(raw: Raw, dt: float, grid: NDArray, rate: float, name: str = "", src: str = "") -> NDArray:
    """A channel on the grid: its own samples when they lie on the grid (`_grid_slice`); else an anti-alias
    low-pass first when its rate is above the grid's, then a cubic spline."""
    t, y = raw.t, raw.y
    own = 1.0 / dt
    if own <= rate * (1 + RATE_MATCH) and (keep := _grid_slice(raw, dt, grid)) is not None:
        return y[keep].copy()
    if own > rate * (1 + RATE_MATCH):
        from scipy.signal import butter, sosfiltfilt  # 0.9 s to import (it loads scipy.stats): only when filtering

        if not uniform(t, dt):  # filter on a uniform grid: resample the jittered stamps at their median rate first
            tu = t[0] + np.arange(int(math.floor((t[-1] - t[0]) / dt + 1e-9)) + 1) * dt
            y, t = cubic_spline(t, y, tu), tu
        sos = butter(DOWNSAMPLE_ORDER, DOWNSAMPLE_CUTOFF * rate, fs=own, output="sos")
        pad = 3 * (2 * sos.shape[0] + 1 - min(int((sos[:, 2] == 0).sum()), int((sos[:, 5] == 0).sum())))
        if y.size <= pad:  # sosfiltfilt's padding at either end (its default padlen)
            raise InputError(
                f"channel {name}: {y.size} samples at {own:g} Hz are too few to low-pass it before it is "
                f"down-sampled onto the {rate:g} Hz grid (the filter needs more than {pad}); read it at its own "
                f"rate (data.rate) or give a longer record",
                source=src,
            )
        y = sosfiltfilt(sos, y)
    return cubic_spline(t, y, grid)


def cubic_spline(t: NDArray, y: NDArray, at: NDArray) -> NDArray:
    """The not-a-knot cubic spline through (t, y) (t increasing, 1-D) at the times `at`, extrapolated beyond t's ends
    by its end pieces: what `scipy.interpolate.CubicSpline(t, y)(at)` gives, by its equations and in its order of
    operations (the same numbers), without importing scipy.interpolate, which loads scipy.optimize, sparse, spatial and
    special (13 MiB of memory and 0.2 s) for a record whose slower channels are up-sampled onto the grid."""
    from scipy.linalg import solve_banded  # (scipy.linalg is loaded already: numpy's and numba's BLAS)

    t, y, at = (np.asarray(a, dtype=float) for a in (t, y, at))
    n = t.size
    if n < 2 or y.shape != t.shape:
        raise ValueError(f"a cubic spline needs at least 2 points with one value each, got {t.shape} and {y.shape}")
    dx = np.diff(t)
    slope = np.diff(y) / dx
    if n == 2:  # a straight line
        s = np.array([slope[0], slope[0]])
    elif n == 3:  # not-a-knot at both ends of one interior knot: the parabola through the three points
        A = np.array([[1.0, 1.0, 0.0], [dx[1], 2 * (dx[0] + dx[1]), dx[0]], [0.0, 1.0, 1.0]])
        b = np.array([2 * slope[0], 3 * (dx[0] * slope[1] + dx[1] * slope[0]), 2 * slope[1]])
        s = np.linalg.solve(A, b)
    else:  # the slopes at the knots: a tridiagonal system, its first and last rows the not-a-knot conditions
        A = np.zeros((3, n))
        b = np.empty(n)
        A[1, 1:-1] = 2 * (dx[:-1] + dx[1:])
        A[0, 2:] = dx[:-1]
        A[-1, :-2] = dx[1:]
        b[1:-1] = 3 * (dx[1:] * slope[:-1] + dx[:-1] * slope[1:])
        A[1, 0], d = dx[1], t[2] - t[0]
        A[0, 1] = d
        b[0] = ((dx[0] + 2 * d) * dx[1] * slope[0] + dx[0] ** 2 * slope[1]) / d
        A[1, -1], d = dx[-2], t[-1] - t[-3]
        A[-1, -2] = d
        b[-1] = (dx[-1] ** 2 * slope[-2] + (2 * d + dx[-1]) * dx[-2] * slope[-1]) / d
        s = solve_banded((1, 1), A, b, overwrite_ab=True, overwrite_b=True, check_finite=False)
    k = (s[:-1] + s[1:] - 2 * slope) / dx  # each piece's power coefficients, about its left knot
    c0, c1, c2, c3 = k / dx, (slope - s[:-1]) / dx - k, s[:-1], y[:-1]
    i = np.clip(np.searchsorted(t, at, side="right") - 1, 0, n - 2)  # the piece of each time (the last: its end too)
    h = at - t[i]
    h2 = h * h
    return c3[i] + c2[i] * h + c1[i] * h2 + c0[i] * (h2 * h)


# ------------------------------------------------------------------------------------------ resample=False


def refuse_resampling(
    raw: Mapping[str, Raw],
    channels: Mapping[str, str],
    steps: Mapping[str, float],
    rates: Mapping[str, float],
    rate: float | None,
    src: str,
) -> None:
    """`resample=False`: every channel uniform and at one rate (within RATE_MATCH), that of `rate` if given."""
    for ours, r in raw.items():
        if not uniform(r.t, steps[ours]):
            steps_ = np.diff(r.t)
            raise InputError(
                f"channel '{ours}' ('{channels[ours]}'): time stamps{_named(r.time, ' in')} jitter (steps "
                f"{steps_.min():.6g} to {steps_.max():.6g} s about the median {steps[ours]:.6g} s): reading them "
                f"means resampling at the median rate; {RESAMPLE_HINT}",
                source=src,
            )
    reference = rate if rate is not None else max(rates.values())
    if any(abs(f - reference) > RATE_MATCH * reference for f in rates.values()):
        listed = ", ".join(f"'{ours}' ('{channels[ours]}') {f:g} Hz" for ours, f in rates.items())
        what = f"differ from the grid rate {rate:g} Hz" if rate is not None else "differ"
        raise InputError(
            f"the channels' rates {what}: {listed}; one grid for them means resampling; {RESAMPLE_HINT}",
            source=src,
        )


def refuse_off_grid(ours: str, theirs: str, raw: Raw, dt: float, grid: NDArray, src: str) -> None:
    """`resample=False`: a channel at the grid rate whose samples are not on the common grid (a phase between
    grid points, or a rate within 1 % of the grid's that drifts off it)."""
    if _grid_slice(raw, dt, grid) is None:
        k = int(np.argmin(np.abs(raw.t - grid[0])))
        raise InputError(
            f"channel '{ours}' ('{theirs}'): its samples are not on the common grid ({grid.size} samples from "
            f"{grid[0]:.9g} s at {1 / (grid[1] - grid[0]):g} Hz; its nearest sample to the start is at "
            f"{raw.t[k]:.9g} s, its step {dt:.9g} s): reading it means resampling; {RESAMPLE_HINT}",
            source=src,
        )


# ------------------------------------------------------------------------------------------ native samples


def native_samples(
    t: NDArray, grid_rate: float, name: str, own_rate: float, stamps: NDArray, source: str, nearest: bool = False
) -> NDArray[np.intp]:
    """The grid indices (into `t`, uniform at `grid_rate`) at which channel `name` (its own rate `own_rate`, its
    sample times `stamps` on the axis of `t`) was sampled in the file: `Record.native_samples` says which."""
    n = t.size
    if own_rate >= grid_rate * (1 - RATE_MATCH):
        return np.arange(n)
    position = (stamps - t[0]) * grid_rate
    k = np.rint(position)
    off = np.abs(position - k)
    if off.size and float(np.max(off)) > NATIVE_MATCH:
        if not nearest:
            worst = int(np.argmax(off))
            raise InputError(
                f"channel '{name}' ({own_rate:g} Hz) is not sampled on points of the {grid_rate:g} Hz "
                f"grid: its sample at t = {stamps[worst]:.9g} s is {off[worst]:.3g} of a step from "
                f"the nearest; nearest=True gives the nearest grid points (values interpolated there), or read "
                f"the file at a grid rate its samples fall on",
                source=source,
            )
        return np.unique(np.clip(k, 0, n - 1)).astype(np.intp)
    return k.astype(np.intp)
