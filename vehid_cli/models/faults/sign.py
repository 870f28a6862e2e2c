"""A sensor mounted upside down (or its sign inverted in the chain): the recorded channel is -y. Seen as a strong
negative correlation with the configured model's prediction, and, for a DC accelerometer, as -1 g at rest where an
upright one reads +1 g."""

from __future__ import annotations

from .base import FAIL, Channel, Context, Correction, Fault, Finding, correlation
from .delay import lag_of

G = 9.80665
NEGATIVE = -0.3  # a correlation this negative with the prediction is a flipped channel (a 30 % off car stays > 0.5)


def check(ch: Channel, channels: tuple[Channel, ...]) -> Finding | None:
    c = correlation(ch.y, ch.pred)
    static = ch.family == "acc" and ch.raw is not None and abs(ch.raw_mean + G) < 0.15 * G
    _lag, peak = lag_of(ch.y, ch.pred, ch.dt) if ch.dt > 0 else (0.0, c)
    delayed = peak > max(-c, 0.5)  # a lag explains it better than a flip: the delay check's finding, not this one
    if (c < NEGATIVE or (static and c < 0.0)) and not delayed:
        upright = "where an upright accelerometer reads +1 g"
        at_rest = f"; at rest it reads {ch.raw_mean / G:+.2f} g {upright}" if static else ""
        return Finding(
            ch.name, "sign", FAIL, c,
            f"{ch.name} runs against the configured model: correlation {c:+.2f} with its prediction{at_rest}; "
            "mounted upside down or its sign inverted",
            fault="sign", start={"sign": -1.0},
            fix=f"flip its sign in the config: data.invert: [{ch.name}] (or remount the sensor)",
        )  # fmt: skip
    return Finding(ch.name, "sign", "ok", c, f"correlation {c:+.2f} with the prediction")


def correct(y, theta, ctx: Context):
    return theta[:, :1] * y  # the recorded channel is g y, g near -1


def correction(ch: Channel, finding: Finding) -> Correction:
    return Correction(("sign",), ((-3.0, -0.3),), (-1.0,), (1.0,))


FAULT = Fault("sign", __doc__.splitlines()[0], stops=True, check=check, correct=correct, correction=correction,
              order=10, unit="-")  # fmt: skip
