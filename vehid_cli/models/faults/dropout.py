"""Held samples: a logger that repeats the last value when a sample is lost (or a stuck sensor). Seen as runs of
identical consecutive values away from the channel's extremes; the loop gives the model those samples, so the channel
loses its held samples, not the run."""

from __future__ import annotations

import numpy as np

from .base import OK, WARNING, Channel, Context, Correction, Fault, Finding
from .clip import RUN, clipped, long_runs

MIN_FRACTION = 0.002  # of the samples held before it is worth a warning


def held(x: np.ndarray) -> np.ndarray:
    """(n,) bool: samples that repeat the one before them exactly, in runs of at least RUN (clipped ones excluded)."""
    runs = long_runs(np.r_[False, x[1:] == x[:-1]], RUN - 1)  # a repeat run of RUN - 1 is RUN equal samples
    out = runs | np.r_[runs[1:], False]  # with the sample each run repeats
    return out & ~clipped(x)


def check(ch: Channel, channels: tuple[Channel, ...]) -> Finding | None:
    mask = held(ch.recorded)
    frac = float(mask.mean()) if mask.size else 0.0
    if mask.sum() >= RUN and frac >= MIN_FRACTION:
        return Finding(
            ch.name, "dropout", WARNING, frac,
            f"{ch.name} repeats its value in runs ({100 * frac:.2g} % of its samples): dropped samples held by the "
            "logger, or a stuck sensor",
            fault="dropout", start={"dropout": 1.0}, fix=f"check {ch.name}'s connection and the logger's buffer",
        )  # fmt: skip
    return Finding(ch.name, "dropout", OK, frac, "no held samples")


def correct(y, theta, ctx: Context):
    h = theta[:, :1]
    return y + h * ctx.mask * (ctx.measured - y)


def correction(ch: Channel, finding: Finding) -> Correction:
    mask = held(ch.recorded)
    return Correction(("dropout",), ((0.0, 1.0),), (1.0,), (0.0,), df=int(mask.sum()), mask=mask)


FAULT = Fault("dropout", __doc__.splitlines()[0], stops=False, check=check, correct=correct, correction=correction,
              order=60, unit="-")  # fmt: skip
