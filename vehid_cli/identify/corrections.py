"""Corrections of the measurement chain a fit carries: unknowns named ``sensor:<channel>:<param>`` (a flipped sign's
gain, a unit's gain, a delay, a swap's weight, a drift, an offset, the weight of clipped or held samples) make the
model's channel what the faulty chain recorded (`models/faults`: each fault's `correct`), so the car is fitted to
the data the chain really gave. At their null values the corrections change nothing (the model without them is
nested in the model with them)."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..models.faults import Context, Fault

SENSOR = "sensor:"


def is_sensor_unknown(name: str) -> bool:
    """``sensor:<channel>:<param>`` names a correction of the measurement chain."""
    return name.startswith(SENSOR)


def split_sensor(name: str) -> tuple[str, str]:
    """(channel, parameter) of ``sensor:<channel>:<param>`` (a swap's parameter is ``swap:<other>``)."""
    channel, _, param = name.removeprefix(SENSOR).partition(":")
    return channel, param


@dataclass(frozen=True)
class SensorCorrection:
    """One fault's correction of one channel (and, for a swap, of its partner): its unknowns, where the channel is
    (family and column of the layout's block) and what the fault's `correct` needs besides the model's channel."""

    names: tuple[str, ...]
    fault: Fault
    family: str
    column: int
    partner: int | None
    context: Context

    def samples(self, start: int, stop: int) -> SensorCorrection:
        """The correction of samples start .. stop - 1 alone (its context cut to them): the same numbers there as
        the whole record's where the fault is `local`."""
        c = self.context
        cut = Context(c.t[start:stop], None if c.measured is None else c.measured[start:stop],
                      None if c.mask is None else c.mask[start:stop])  # fmt: skip
        return dataclasses.replace(self, context=cut)


def corrected(
    corrections: tuple[SensorCorrection, ...], outputs: dict[str, NDArray], values: Mapping[str, NDArray]
) -> dict[str, NDArray]:
    """The model's channels (family -> (P, n, k), changed in place) as the faulty chain records them, for the
    correction unknowns' `values` ((P,) each)."""
    for c in corrections:
        block = outputs[c.family]
        theta = np.column_stack([np.broadcast_to(np.asarray(values[n], dtype=float), block.shape[:1]) for n in c.names])
        own = block[:, :, c.column].copy()
        if c.partner is None:
            block[:, :, c.column] = c.fault.correct(own, theta, c.context)
            continue
        other = block[:, :, c.partner].copy()
        block[:, :, c.column] = c.fault.correct(own, theta, _with_partner(c.context, other))
        block[:, :, c.partner] = c.fault.correct(other, theta, _with_partner(c.context, own))
    return outputs


def _with_partner(ctx: Context, partner: NDArray) -> Context:
    return Context(ctx.t, ctx.measured, ctx.mask, partner)
