"""What a fault of the measurement chain is: how a check finds it by holding a measured channel against the configured
model's prediction of it, and how the model reproduces it (the correction the closed loop fits, `sensor:<ch>:<fault>`).

The model is the best instrument to check the measurement: the configured car predicts every channel's sign, scale,
timing and range, and stays a good enough instrument when the car is 30 % off (checks compare shapes and orders of
magnitude, never the fine values a fit would change). A fault module defines one `Fault` (`FAULT`); the package
registers every module it holds.

The contract of a correction: `correct(y, theta, ctx)` maps the model's channel y (P, n) (and, for a fault that
involves a second channel, `ctx.partner` (P, n)) with the fault's parameters theta (P, m) to what the faulty chain
would have recorded; at the parameters' `null` values it is y itself (no fault), so the model with the correction is
nested in the model without it. A correction that reads only each sample's own values (`local`) gives the same
numbers on any stretch of samples with its context cut to it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

OK, WARNING, FAIL = "ok", "warning", "fail"


@dataclass(frozen=True)
class Channel:
    """A measured channel beside the configured model's prediction of it, at the channel's own samples."""

    name: str  # the layout name
    family: str  # acc or disp
    column: int  # its column in the family's block
    kind: str  # the sensor kind (body_acc, wheel_acc, body_disp, wheel_disp, deflection)
    t: NDArray  # (m,) sample times [s] (the channel's own samples)
    y: NDArray  # (m,) measured [SI], its mean removed
    pred: NDArray  # (m,) the configured model's prediction [SI], its mean removed
    sigma: float  # the noise standard deviation the fit would weight it with [SI]
    raw: NDArray | None = None  # (m,) the channel as read [SI], before any offset is removed (None: as y)
    pred_mean: float = 0.0  # the prediction's mean [SI] (y and pred have theirs removed)
    unit: str = ""  # the unit it was read in ('' SI)
    offsets_free: bool = False  # the fit profiles an offset per channel (data.offsets: identify) or removed them

    @property
    def recorded(self) -> NDArray:
        """The channel as read [SI], before any offset was removed."""
        return self.y if self.raw is None else self.raw

    @property
    def raw_mean(self) -> float:
        return float(np.mean(self.recorded))

    @property
    def dt(self) -> float:
        return float(np.median(np.diff(self.t))) if self.t.size > 1 else 0.0


@dataclass(frozen=True)
class Finding:
    """What one check says of one channel (SPEC section 6: channel, check, status, value, message); `fault` names the
    fault it points to (``sign``, ``gain``, ``swap:<other>`` ...; None for a check of no fault), `start` the values
    of the fault's parameters it measured (the loop starts the fault's fit there) and `fix` what to change."""

    channel: str
    check: str
    status: str  # ok, warning or fail
    value: float
    message: str
    fault: str | None = None
    start: dict[str, float] = field(default_factory=dict)
    fix: str = ""

    def to_json(self) -> dict:
        value = float(self.value) if np.isfinite(self.value) else None
        return {"channel": self.channel, "check": self.check, "status": self.status, "value": value,
                "message": self.message}  # fmt: skip


@dataclass(frozen=True)
class Context:
    """What a correction may need besides the model's channel: the sample times [s], the partner channel of a pair,
    the measured channel itself (clipped or held samples are the measured ones) and a mask of the samples it acts
    on."""

    t: NDArray
    measured: NDArray | None = None
    mask: NDArray | None = None
    partner: NDArray | None = None


@dataclass(frozen=True)
class Correction:
    """How the loop fits a fault on a channel: its parameters' names (after ``sensor:<ch>:``), search ranges, start
    and null values, and the degrees of freedom of its test (None: one per parameter)."""

    params: tuple[str, ...]
    limits: tuple[tuple[float, float], ...]
    start: tuple[float, ...]
    null: tuple[float, ...]
    df: int | None = None
    mask: NDArray | None = None  # the samples it acts on (clip, dropout), in the channel's own samples


@dataclass(frozen=True, eq=False)
class Fault:
    """A fault of the measurement chain (see the module doc)."""

    name: str
    doc: str
    stops: bool  # a failed check of it makes any fit meaningless: identify stops (exit 2) unless --no-checks
    check: Callable[[Channel, tuple[Channel, ...]], Finding | None]  # (the channel, all channels) -> a finding
    correct: Callable[[NDArray, NDArray, Context], NDArray]  # (y (P, n), theta (P, m), ctx) -> recorded (P, n)
    correction: Callable[[Channel, Finding], Correction]  # how the loop fits it, from the check's finding
    order: int = 0  # the order checks run and findings are listed in
    unit: str = "-"  # the SI unit of its correction's parameter ('{channel}': the channel's own; '-': none)
    pair: bool = False  # acts on two channels (a swap): `ctx.partner` is the other's model channel
    local: bool = True  # each sample's correction reads only that sample (of y, ctx.t, ctx.measured, ctx.mask, the
    # partner): a long record's blocks are corrected alone (identify/forward.py); a delay or a drift about the
    # record's middle is not


def correlation(a: NDArray, b: NDArray) -> float:
    """Pearson correlation of two equal-length series (0 when either is constant)."""
    a, b = a - a.mean(), b - b.mean()
    den = float(np.sqrt(np.dot(a, a) * np.dot(b, b)))
    return float(np.dot(a, b) / den) if den > 0 else 0.0
