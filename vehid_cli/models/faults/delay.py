"""A channel on a delayed clock (a logger group triggered late, a filter's lag): the recorded channel is y(t - tau).
Seen as the lag at which it best matches the configured model's prediction, against the other channels' lags (the
model's own phase error, a car 30 % off, moves every channel alike)."""

from __future__ import annotations

import weakref

import numpy as np

from .base import OK, WARNING, Channel, Context, Correction, Fault, Finding

MAX_LAG = 0.1  # [s] the lags searched
MIN_LAG = 0.004  # [s] a lag below this (or two samples) is not worth a warning
PHASE = 0.04  # nor a lag below this fraction of the channel's typical period (a model's phase error grows with it)
HINT = 0.006  # [s] ... but a lag beyond this one is a possible delay all the same: the closed loop tests it (a car
# 30 % off the configured one moves a channel's lag against the others' by at most 3.4 ms on the paper's bump)


def period(pred: np.ndarray, dt: float) -> float:
    """The prediction's typical period [s]: twice the record over its number of zero crossings."""
    crossings = int(np.count_nonzero(np.diff(np.signbit(pred))))
    return 2.0 * pred.size * dt / max(crossings, 1)


def lag_limit(ch: Channel) -> float:
    """The smallest lag [s] of this channel that is a delay whatever the model's phase."""
    return max(MIN_LAG, 2 * ch.dt, PHASE * period(ch.pred, ch.dt))


def hint_limit(ch: Channel) -> float:
    """The smallest lag [s] of this channel worth a warning (a possible delay below lag_limit)."""
    return min(lag_limit(ch), max(HINT, 2 * ch.dt))


_LAGS: dict[tuple[int, int, float], tuple[weakref.ref, weakref.ref, tuple[float, float]]] = {}


def lag_of(y: np.ndarray, pred: np.ndarray, dt: float) -> tuple[float, float]:
    """The lag [s] of y behind pred at the peak of their cross-correlation (parabolic between samples), and the
    correlation there. Remembered while y and pred live: each channel's check compares its lag with every other
    channel's, which recomputed C² cross-correlations (a 60 s record's 16 channels: 800 FFTs, seconds)."""
    key = (id(y), id(pred), dt)
    seen = _LAGS.get(key)
    if seen is not None and seen[0]() is y and seen[1]() is pred:
        return seen[2]
    if len(_LAGS) > 256:  # forget the channels that are gone
        for k in [k for k, v in _LAGS.items() if v[0]() is None or v[1]() is None]:
            del _LAGS[k]
    out = _lag_of(y, pred, dt)
    try:
        _LAGS[key] = (weakref.ref(y), weakref.ref(pred), out)
    except TypeError:  # not an array that takes weak references: not remembered
        pass
    return out


def _lag_of(y: np.ndarray, pred: np.ndarray, dt: float) -> tuple[float, float]:
    n = y.size
    k = max(1, min(int(round(MAX_LAG / dt)), n // 4))
    size = 1 << int(np.ceil(np.log2(2 * n)))
    xc = np.fft.irfft(np.fft.rfft(y, size) * np.conj(np.fft.rfft(pred, size)), size)
    lags = np.r_[xc[-k:], xc[: k + 1]]  # lags -k..k
    j = int(np.argmax(lags))
    shift = 0.0
    if 0 < j < lags.size - 1:
        a, b, c = lags[j - 1], lags[j], lags[j + 1]
        den = a - 2 * b + c
        shift = 0.5 * (a - c) / den if den != 0 else 0.0
    norm = float(np.sqrt(np.dot(y, y) * np.dot(pred, pred))) or 1.0
    return (j - k + shift) * dt, float(lags[j] / norm)


def check(ch: Channel, channels: tuple[Channel, ...]) -> Finding | None:
    dt = ch.dt
    if dt <= 0:
        return None
    lag, peak = lag_of(ch.y, ch.pred, dt)
    others = [lag_of(c.y, c.pred, c.dt)[0] for c in channels if c.name != ch.name and c.dt > 0]
    typical = float(np.median(others)) if others else 0.0
    relative = lag - typical
    if abs(relative) > hint_limit(ch) and peak > 0.3:
        why = ("a delayed clock or filter in its chain" if abs(relative) > lag_limit(ch) else
               "a delayed clock or filter in its chain, or the model's phase (`vehid diagnose` tests it)")  # fmt: skip
        return Finding(
            ch.name, "delay", WARNING, lag,
            f"{ch.name} lags the configured model's prediction by {1e3 * lag:.1f} ms where the other channels lag "
            f"{1e3 * typical:.1f} ms: {why}",
            fault="delay", start={"delay": lag}, fix=f"check the time base of {ch.name}'s logger group",
        )  # fmt: skip
    return Finding(ch.name, "delay", OK, lag, f"lag {1e3 * lag:.1f} ms (the channels' median {1e3 * typical:.1f} ms)")


def correct(y, theta, ctx: Context):
    """y(t - tau) on the uniform grid t, linear between samples (the first value held before the start)."""
    t = ctx.t
    out = np.empty_like(y)
    for p in range(y.shape[0]):
        out[p] = np.interp(t - theta[p, 0], t, y[p])
    return out


def correction(ch: Channel, finding: Finding) -> Correction:
    return Correction(("delay",), ((-MAX_LAG, MAX_LAG),), (float(finding.start.get("delay", 0.0)),), (0.0,))


FAULT = Fault("delay", __doc__.splitlines()[0], stops=False, check=check, correct=correct, correction=correction,
              order=40, unit="s", local=False)  # fmt: skip
