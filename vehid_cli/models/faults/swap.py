"""Two connectors swapped: channel a records what b measures and b what a measures. Seen as each channel resembling
the other's prediction clearly better than its own; or, for two channels whose predictions look alike (the left and
right sensors of one axle over a bump), as the pair's difference running against its prediction while their sum
follows its own: a swap turns a - b into b - a and leaves a + b as it was. A channel upside down turns the sum as
well, a wrong unit factor leaves the pair fitting its own predictions better than each other's."""

from __future__ import annotations

import numpy as np

from .base import FAIL, Channel, Context, Correction, Fault, Finding, correlation

MARGIN = 0.15  # how much better the other's prediction must fit, both ways
RESEMBLES = 0.5  # and how well at least (a channel that fits nothing, e.g. delayed, is no swap)
CROSSED = 0.5  # a pair's difference fits its prediction turned over with below this share of the misfit: swapped


def check(ch: Channel, channels: tuple[Channel, ...]) -> Finding | None:
    own = correlation(ch.y, ch.pred)
    best = None
    for other in channels:
        if other.name == ch.name or other.family != ch.family or other.y.size != ch.y.size:
            continue
        mine, theirs = correlation(ch.y, other.pred), correlation(other.y, ch.pred)
        back = correlation(other.y, other.pred)
        better = mine > max(own, 0.0) + MARGIN and theirs > max(back, 0.0) + MARGIN
        if (better and min(mine, theirs) > RESEMBLES or crossed(ch, other)) and (best is None or mine > best[1]):
            best = (other, mine, theirs)
    if best is None:
        return Finding(ch.name, "swap", "ok", own, "its own prediction fits it best")
    other, mine, theirs = best
    return Finding(
        ch.name, "swap", FAIL, mine,
        f"{ch.name} looks like {other.name}'s prediction (correlation {mine:+.2f} against {own:+.2f} with its own; "
        f"{ch.name} - {other.name} against its prediction {correlation(ch.y - other.y, ch.pred - other.pred):+.2f}) "
        f"and {other.name} like {ch.name}'s ({theirs:+.2f}): the two connectors are swapped",
        fault=f"swap:{other.name}", start={f"swap:{other.name}": 1.0},
        fix=f"swap them in the config: data.swap: [[{ch.name}, {other.name}]] (or swap the connectors)",
    )  # fmt: skip


def crossed(a: Channel, b: Channel) -> bool:
    """Do a and b look swapped by their difference and sum: a - b against its prediction (its misfit with the
    prediction's sign turned below CROSSED of its misfit with the prediction), a + b with its own? The difference
    leaves out what the two share, so a car off the configured one in what moves both (its mass) does not hide it."""
    d, p = a.y - b.y, a.pred - b.pred
    if correlation(d, p) > -RESEMBLES or correlation(a.y + b.y, a.pred + b.pred) < RESEMBLES:
        return False
    return float(np.sum((d + p) ** 2)) < CROSSED * float(np.sum((d - p) ** 2))


def correct(y, theta, ctx: Context):
    w = theta[:, :1]
    return (1.0 - w) * y + w * ctx.partner


def correction(ch: Channel, finding: Finding) -> Correction:
    name = finding.fault.partition(":")[2]
    return Correction((f"swap:{name}",), ((0.0, 1.0),), (1.0,), (0.0,))


FAULT = Fault("swap", __doc__.splitlines()[0], stops=True, check=check, correct=correct, correction=correction,
              order=30, unit="-", pair=True)  # fmt: skip
