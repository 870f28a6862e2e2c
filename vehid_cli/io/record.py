"""A recorded run (`Record`): named channels in SI units on one uniform time grid, what `io.read.read_record` gives
for any logger file, with each channel's own rate and sample times kept; and `remove_offset`, its channels less
their offsets (accelerometers' gravity and bias)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from ..core.errors import InputError
from ..core.hints import did_you_mean
from .timegrid import native_samples


@dataclass(frozen=True)
class Record:
    """A recorded run: channels (our names) in SI units on one uniform time grid.

    `rates` and `stamps` keep what the grid hides: a channel's own sampling rate in the file and its own sample
    times, so that a channel up-sampled onto the grid can be compared at its own samples only
    (`native_samples`) rather than at the spline values between them."""

    t: NDArray  # (n,) [s] since the start of the record, uniform
    channels: dict[str, NDArray]  # name -> (n,) values in SI units
    source: str
    rates: dict[str, float]  # name -> its own sampling rate in the file [Hz] (`timegrid.rate_of`: of its time vector)
    # name -> its own sample times [s] on the axis of `t` (the file's stamps less the record's start), those
    # within [t[0], t[-1]] (to 1e-3 of a grid step): after a window, those inside the window
    stamps: dict[str, NDArray]
    declared: dict[str, str] = field(default_factory=dict)  # name -> the unit its file declares ('' none)

    @property
    def rate(self) -> float:
        """Sampling rate [Hz]."""
        return float((self.t.size - 1) / (self.t[-1] - self.t[0]))

    def channel(self, name: str) -> NDArray:
        if name not in self.channels:
            raise InputError(
                f"no channel '{name}' in the record{did_you_mean(name, self.channels)} "
                f"(channels: {', '.join(self.channels)})",
                source=self.source,
            )
        return self.channels[name]

    def native_samples(self, name: str, *, nearest: bool = False) -> NDArray[np.intp]:
        """The grid indices (into `t` and the channel) at which channel `name` was sampled in the file.

        - at the grid rate or faster (within 1 %, `timegrid.RATE_MATCH`): every index. Every grid point then
          carries the channel, though not always a sample of the file: stamps off the grid were interpolated, and a
          faster channel was low-passed before it was down-sampled (see `io.timegrid`);
        - slower, with every sample within 1e-3 of a step of a grid point (its rate an integer fraction of the grid
          rate, its samples in phase with the grid: a 200 Hz channel on a 1 kHz grid): the indices of those grid
          points, where the values are the file's samples (to round-off; between them they are a cubic spline);
        - slower but off the grid (a rate that does not divide the grid rate, a phase between grid points, or
          jittered stamps): no grid point holds its samples, so this is an InputError, unless `nearest`: then the
          (distinct) grid points nearest to its samples, up to half a step away, where the values are
          interpolated, not sampled; compare at them knowing so.

        After a window the indices refer to the windowed grid."""
        self.channel(name)
        return native_samples(
            self.t, self.rate, name, self.rates[name], self.stamps[name], self.source, nearest=nearest
        )


def remove_offset(record: Record, names: Sequence[str], mode: str = "mean") -> Record:
    """The record with the named channels' offsets removed: their mean over the whole record (`mean`) or over
    its first second (`first_second`: the car at rest before the run), e.g. accelerometers' gravity and bias."""
    if mode not in ("mean", "first_second"):
        raise InputError(f"unknown offset mode '{mode}'; expected mean or first_second", source=record.source)
    keep = slice(None)
    if mode == "first_second":
        keep = record.t < record.t[0] + 1.0
        if record.t[-1] - record.t[0] < 1.0:
            raise InputError(
                f"the record lasts {record.t[-1] - record.t[0]:g} s, less than one second", source=record.source
            )
    channels = dict(record.channels)
    for name in names:
        y = record.channel(name)
        channels[name] = y - float(np.mean(y[keep]))
    return replace(record, channels=channels)
