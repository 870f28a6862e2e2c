"""A drifting bias (a warming accelerometer, a creeping potentiometer zero): the recorded channel is y + s (t - t_mid).
Seen as a trend of the channel against the configured model's prediction that the model's oscillations cannot make."""

from __future__ import annotations

import numpy as np

from .base import OK, WARNING, Channel, Context, Correction, Fault, Finding
from .clip import clipped
from .dropout import held

SIGNIFICANT = 0.2  # a drift over the record this large against the channel's spread is worth a warning
LINEAR = 0.5  # ... when the straight line explains at least this share of the departure from the prediction


def trend(ch: Channel) -> tuple[float, float, float]:
    """The slope [SI/s] of the measured channel's departure from (a multiple of) the prediction, the drift over the
    record relative to the channel's spread, and the share of the departure's variance the straight line explains
    (a drifting bias is a clean ramp; a model's error oscillates with the motion)."""
    keep = ~(clipped(ch.recorded) | held(ch.recorded))  # a saturated or held stretch is not a trend
    p, y, t = ch.pred[keep], ch.y[keep], ch.t[keep]
    if t.size < 3:
        return 0.0, 0.0, 0.0
    b = float(np.dot(y, p) / np.dot(p, p)) if np.dot(p, p) > 0 else 0.0
    e = y - b * p
    tc = t - t.mean()
    slope = float(np.dot(e, tc) / np.dot(tc, tc)) if np.dot(tc, tc) > 0 else 0.0
    span = float(ch.t[-1] - ch.t[0]) if ch.t.size else 0.0
    spread = float(np.std(ch.y)) or 1.0
    var = float(np.var(e))
    share = slope**2 * float(np.var(tc)) / var if var > 0 else 0.0
    return slope, abs(slope) * span / spread, share


def check(ch: Channel, channels: tuple[Channel, ...]) -> Finding | None:
    slope, relative, share = trend(ch)
    if relative > SIGNIFICANT and share > LINEAR:
        return Finding(
            ch.name, "drift", WARNING, slope,
            f"{ch.name} drifts by {relative:.2g} x its spread over the record ({slope:.3g} SI/s) against the "
            "configured model: a drifting bias",
            fault="drift", start={"drift": slope}, fix=f"check {ch.name}'s bias stability (or its zero)",
        )  # fmt: skip
    return Finding(ch.name, "drift", OK, slope, f"drift {relative:.2g} x its spread")


def correct(y, theta, ctx: Context):
    t = ctx.t
    return y + theta[:, :1] * (t - 0.5 * (t[0] + t[-1]))[None, :]


def correction(ch: Channel, finding: Finding) -> Correction:
    s = float(finding.start.get("drift", 0.0))
    width = max(10 * abs(s), 1e-12)
    return Correction(("drift",), ((-width, width),), (s,), (0.0,))


FAULT = Fault("drift", __doc__.splitlines()[0], stops=False, check=check, correct=correct, correction=correction,
              order=70, unit="{channel}/s", local=False)  # fmt: skip
