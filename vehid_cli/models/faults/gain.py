"""A channel recorded in another unit than the config (or the file) declares, or with a wrong gain in the chain: the
recorded channel is g y. Seen as the ratio of its spread to the prediction's: the classic unit factors (9.81 between
g and m/s², 1000 between mm and m, 100, 25.4, 10) are named with the unit that fits; a ratio far from 1 that is
none of them is a gain."""

from __future__ import annotations

import math

import numpy as np

from ...core.units import UNITS
from .base import FAIL, OK, WARNING, Channel, Context, Correction, Fault, Finding

G = 9.80665
FACTORS = (9.80665, 1000.0, 100.0, 25.4, 10.0)  # the unit slips worth naming (and their reciprocals)
FAMILY_QUANTITY = {"acc": "acceleration", "disp": "displacement"}
NEAR = 1.6  # a ratio within this factor of a classic one is that unit slip (a 30 % off car moves it less)
FINE, MEANINGLESS = 2.0, 5.0  # within FINE: as expected; beyond MEANINGLESS: no fit can mean anything
HINT = 1.25  # a spread off the family's other channels' by more than this (within FINE) is a possible gain: the closed
# loop tests it (a warning). Against the others': a car off the configured one, or an effect it lacks, moves every
# channel's spread alike (the paper's bump runs with asymmetric damping: 0.75-0.80 on all four accelerometers)


def ratio(ch: Channel) -> float:
    """Spread of the measured channel over the prediction's, the noise taken out of the measured one."""
    var = float(np.var(ch.y)) - ch.sigma**2
    sp = float(np.std(ch.pred))
    return math.sqrt(max(var, 0.25 * float(np.var(ch.y)))) / sp if sp > 0 else float("nan")


def _unit_slip(r: float) -> float | None:
    """The classic factor F (or 1/F) closest to r, if within NEAR of it, else None."""
    candidates = [c for f in FACTORS for c in (f, 1.0 / f)]
    best = min(candidates, key=lambda c: abs(math.log(r / c)))
    return best if abs(math.log(r / best)) < math.log(NEAR) else None


def _suggested_unit(ch: Channel, r: float) -> str | None:
    """The unit of the channel's quantity whose factor to SI is the declared one over r (the file's real unit)."""
    table = UNITS.get(FAMILY_QUANTITY.get(ch.family, ""), {})
    declared = table.get(ch.unit or next(iter(table), ""), 1.0)
    want = declared / r
    best = min(table, key=lambda u: abs(math.log(table[u] / want)), default=None)
    return best if best is not None and abs(math.log(table[best] / want)) < math.log(NEAR) else None


def check(ch: Channel, channels: tuple[Channel, ...]) -> Finding | None:
    r = ratio(ch)
    if not np.isfinite(r) or r <= 0:
        return None
    if 1.0 / FINE <= r <= FINE:
        return _within(ch, channels, r)
    slip = _unit_slip(r)
    declared = ch.unit or "SI"
    if slip is not None:
        unit = _suggested_unit(ch, r)
        fix = f"data.units.{ch.name}: {unit}" if unit else f"check the unit of {ch.name} (read as {declared})"
        return Finding(
            ch.name, "scale", FAIL, r,
            f"{ch.name} is {r:.3g} x the configured model's prediction: a unit factor of {slip:.4g} (read as "
            f"{declared}{'; the file holds ' + unit if unit else ''})",
            fault="gain", start={"gain": r}, fix=fix,
        )  # fmt: skip
    status = FAIL if not 1.0 / MEANINGLESS <= r <= MEANINGLESS else WARNING
    why = f"(expected within {1 / FINE:g}-{FINE:g}): a gain in the chain (amplifier, calibration) or a model far off"
    return _gain(ch, status, r, f"{ch.name} is {r:.3g} x the configured model's prediction {why}", r)


def _gain(ch: Channel, status: str, r: float, message: str, start: float) -> Finding:
    """A finding that points to a gain of `start` in the channel's chain (its spread r x the prediction's)."""
    return Finding(ch.name, "scale", status, r, message, fault="gain", start={"gain": start},
                   fix=f"check the calibration of {ch.name}")  # fmt: skip


def _within(ch: Channel, channels: tuple[Channel, ...], r: float) -> Finding:
    """A spread within FINE of the prediction's: a warning when it stands HINT apart from the family's others' (those
    within FINE too: a unit slip beside it is a fault of its own)."""
    family = [ratio(c) for c in channels if c.family == ch.family and c.name != ch.name]
    others = [q for q in family if 1.0 / FINE <= q <= FINE]
    typical = float(np.median(others)) if others else 1.0
    relative = r / typical if typical > 0 else 1.0
    if 1.0 / HINT <= relative <= HINT:
        return Finding(ch.name, "scale", OK, r, f"spread {r:.2f} x the prediction's")
    return _gain(
        ch, WARNING, r,
        f"{ch.name}'s spread is {r:.2f} x the prediction's where the other {ch.family} channels' is {typical:.2f} x: "
        "a gain in the chain (calibration), or the car off the configured one (`vehid diagnose` tests both)",
        relative,
    )  # fmt: skip


def correct(y, theta, ctx: Context):
    return theta[:, :1] * y


def correction(ch: Channel, finding: Finding) -> Correction:
    r = float(finding.start.get("gain", 1.0))
    return Correction(("gain",), ((r / 3.0, r * 3.0),), (r,), (1.0,))


FAULT = Fault("gain", __doc__.splitlines()[0], stops=True, check=check, correct=correct, correction=correction,
              order=20, unit="-")  # fmt: skip
