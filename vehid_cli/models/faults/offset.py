"""An offset the fit does not expect (data.offsets: none): gravity in a DC accelerometer, a bias, a potentiometer's
zero; the recorded channel is y + a. Seen as the channel's mean away from the prediction's by more than its spread."""

from __future__ import annotations

import numpy as np

from .base import OK, WARNING, Channel, Context, Correction, Fault, Finding

G = 9.80665


def check(ch: Channel, channels: tuple[Channel, ...]) -> Finding | None:
    if ch.offsets_free:
        return None
    a = ch.raw_mean - ch.pred_mean
    spread = float(np.std(ch.y)) or 1.0
    if abs(a) > 0.5 * spread and abs(a) > 3 * ch.sigma:
        is_gravity = ch.family == "acc" and abs(abs(a) - G) < 0.2 * G
        gravity = " (gravity: a DC accelerometer reads 1 g at rest)" if is_gravity else ""
        return Finding(
            ch.name, "offset", WARNING, a,
            f"{ch.name} sits {a:.3g} SI away from the prediction's mean{gravity}, {abs(a) / spread:.2g} x its spread",
            fault="offset", start={"offset": a}, fix="set data.offsets: identify (or remove)",
        )  # fmt: skip
    return Finding(ch.name, "offset", OK, a, "no offset")


def correct(y, theta, ctx: Context):
    return y + theta[:, :1]


def correction(ch: Channel, finding: Finding) -> Correction:
    a = float(finding.start.get("offset", 0.0))
    width = 3 * abs(a) + 1e-12
    return Correction(("offset",), ((-width, width),), (a,), (0.0,))


FAULT = Fault("offset", __doc__.splitlines()[0], stops=False, check=check, correct=correct, correction=correction,
              order=80, unit="{channel}")  # fmt: skip
