"""A saturating sensor (or a logger range too small): the recorded channel is flat at its range's end wherever the
motion goes beyond it. Seen as runs of samples at the channel's extreme value; the loop gives the model those
samples (they only say 'beyond the range'), so the channel loses its clipped samples, not the run."""

from __future__ import annotations

import numpy as np

from .base import OK, WARNING, Channel, Context, Correction, Fault, Finding

UNIT = {"acc": "m/s²", "disp": "m"}
MIN_SAMPLES = 5  # at the extreme, in runs of at least RUN samples
RUN = 3


def long_runs(flags: np.ndarray, length: int) -> np.ndarray:
    """(n,) bool: the flags that belong to a run of at least `length` consecutive True flags."""
    edges = np.diff(np.concatenate(([0], flags.astype(np.int8), [0])))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    keep = ends - starts >= length
    step = np.zeros(flags.size + 1, dtype=np.int64)
    step[starts[keep]] += 1
    step[ends[keep]] -= 1
    return np.cumsum(step[:-1]) > 0


def flat_runs(x: np.ndarray, value: float, tol: float) -> np.ndarray:
    """(n,) bool: samples within tol of value that belong to a run of at least RUN such samples."""
    return long_runs(np.abs(x - value) <= tol, RUN)


def clipped(x: np.ndarray) -> np.ndarray:
    """(n,) bool: the samples held at the channel's maximum or minimum."""
    span = float(np.max(x) - np.min(x)) or 1.0
    tol = 1e-9 * span
    return flat_runs(x, float(np.max(x)), tol) | flat_runs(x, float(np.min(x)), tol)


def check(ch: Channel, channels: tuple[Channel, ...]) -> Finding | None:
    mask = clipped(ch.recorded)
    n = int(mask.sum())
    if n >= MIN_SAMPLES:
        levels = sorted({round(float(v), 12) for v in ch.recorded[mask]})
        shown = " and ".join(f"{v:.4g}" for v in dict.fromkeys((levels[0], levels[-1])))
        return Finding(
            ch.name, "clip", WARNING, float(levels[-1]),
            f"{ch.name} is flat at its extreme ({shown} {UNIT[ch.family]}) for {n} samples: the sensor or the logger's "
            "range saturates; those samples say only 'beyond the range'",
            fault="clip", start={"clip": 1.0}, fix=f"widen the range of {ch.name} (or leave its clipped samples out)",
        )  # fmt: skip
    return Finding(ch.name, "clip", OK, 0.0, "no flat extremes")


def correct(y, theta, ctx: Context):
    """At the clipped samples, the recorded values (weight theta): the model is not asked to match them."""
    h = theta[:, :1]
    return y + h * ctx.mask * (ctx.measured - y)


def correction(ch: Channel, finding: Finding) -> Correction:
    mask = clipped(ch.recorded)
    return Correction(("clip",), ((0.0, 1.0),), (1.0,), (0.0,), df=int(mask.sum()), mask=mask)


FAULT = Fault("clip", __doc__.splitlines()[0], stops=False, check=check, correct=correct, correction=correction,
              order=50, unit="-")  # fmt: skip
