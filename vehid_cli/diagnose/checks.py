"""Pre-fit checks of every measured channel against the configured model (`vehid check`, and the first thing `identify`
and `diagnose` do): each registered fault of the measurement chain (`models/faults/`) checks each channel against the
configured car's prediction of it on the run's own road, and the noise is held against the one the fit will assume.

A finding that makes any fit meaningless (a sign, a swap, a unit factor: `Fault.stops`) stops `identify` with exit 2
naming the channel, the evidence and the fix (unless --no-checks); lesser ones are warnings; `diagnose` takes every
finding into its loop as a `sensor:<channel>:<fault>` candidate.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..core.result import Result
from ..identify.task import Task
from ..models.faults import FAIL, FAULTS, OK, WARNING, Channel, Finding
from ..models.faults.delay import lag_limit, lag_of
from ..models.noise import estimate_noise_sigma

NOISE_RATIO = 3.0  # the noise this many times above or below the assumed one is worth a warning
STATUS_ORDER = {OK: 0, WARNING: 1, FAIL: 2}


@dataclass(frozen=True)
class Checks(Result):
    """The findings of every check on every channel of one run (or several: `run` names each finding's)."""

    findings: tuple[Finding, ...]
    runs: tuple[str, ...] = ()  # the file of each finding (several runs checked together), else empty

    def to_json(self) -> list[dict]:
        out = [f.to_json() for f in self.findings]
        if self.runs:
            for doc, run in zip(out, self.runs, strict=True):
                doc["run"] = run
        return out

    @property
    def problems(self) -> tuple[Finding, ...]:
        """The warnings and failures, worst first."""
        return tuple(sorted((f for f in self.findings if f.status != OK), key=lambda f: -STATUS_ORDER[f.status]))

    @property
    def stopping(self) -> tuple[Finding, ...]:
        """The failures that make a fit meaningless (a sign, a swap, a unit factor)."""
        return tuple(f for f in self.findings if f.status == FAIL and f.fault and _stops(f.fault))

    def worst(self, channel: str) -> str:
        """The worst status of a channel's checks."""
        statuses = [f.status for f in self.findings if f.channel == channel]
        return max(statuses, key=lambda s: STATUS_ORDER[s], default=OK)

    def stop_message(self) -> str:
        """Why identify stops: each failure with its evidence and fix."""
        lines = [f"{f.message}; fix: {f.fix}" if f.fix else f.message for f in self.stopping]
        return (
            "the measurement chain is wrong, so any fit would be meaningless: " + " | ".join(lines)
            + " (vehid check shows every channel; --no-checks fits anyway)"
        )  # fmt: skip

    def warnings(self) -> list[str]:
        """One line per warning (and per failure that does not stop a fit)."""
        return [f"{f.check} {f.channel}: {f.message}" for f in self.problems if f not in self.stopping]

    def merged(self, other: Checks, run: str, other_run: str) -> Checks:
        """Two runs' findings in one list, each tagged with its run."""
        mine = self.runs or (run,) * len(self.findings)
        theirs = other.runs or (other_run,) * len(other.findings)
        return Checks(self.findings + other.findings, mine + theirs)


def _stops(fault: str) -> bool:
    base = FAULTS.get(fault.partition(":")[0])
    return bool(base is not None and base.stops)


def noise_finding(ch: Channel, assumed_from_data: bool) -> Finding:
    """The channel's noise (third differences of its samples) against the sigma the fit will weight it with."""
    est = float(estimate_noise_sigma(ch.recorded[:, None])[0])
    q = est / ch.sigma if ch.sigma > 0 else float("nan")
    if assumed_from_data or not np.isfinite(q) or 1 / NOISE_RATIO <= q <= NOISE_RATIO:
        return Finding(ch.name, "noise", OK, q, f"noise {q:.2g} x the assumed sigma")
    what = "understated: the fit will trust it too much" if q > 1 else "overstated: intervals will be too wide"
    return Finding(
        ch.name, "noise", WARNING, q,
        f"{ch.name}'s noise is {q:.2g} x the sigma the fit assumes ({ch.sigma:.3g} SI): the assumed noise is {what}",
        fix="check noise.sigma / the sensor's own sigma",
    )  # fmt: skip


def unit_finding(name: str, unit: str, origin: str) -> Finding:
    """Where a channel's unit came from: the config, the file, or nowhere (SI by default: said, not silent)."""
    if origin.startswith("default"):
        return Finding(name, "unit", WARNING, float("nan"), f"{name} is read as SI: {origin}",
                       fix=f"give its unit: data.units.{name} (or data.units.acc / disp)")  # fmt: skip
    return Finding(name, "unit", OK, float("nan"), f"read in {unit} ({origin})")


def trigger_finding(channels: Sequence[Channel]) -> Finding | None:
    """Every channel lagging the model alike: the road and the responses recorded on different clocks (a trigger
    offset). None when the channels' typical lag is within their typical tolerance."""
    timed = [c for c in channels if c.dt > 0 and c.y.size > 8]
    if len(timed) < 2:
        return None
    lags = np.array([lag_of(c.y, c.pred, c.dt)[0] for c in timed])
    typical = float(np.median(lags))
    limit = float(np.median([lag_limit(c) for c in timed]))
    spread = float(np.median(np.abs(lags - typical)))
    if abs(typical) > limit and spread < 0.5 * abs(typical):
        return Finding(
            "road", "trigger", WARNING, typical,
            f"every channel lags the configured model by about {1e3 * typical:.1f} ms (they agree within "
            f"{1e3 * spread:.1f} ms): the road and the responses were recorded on different clocks (a trigger offset)",
            fix="align the road's time base with the responses' (shift the road channels, or trim with data.window)",
        )  # fmt: skip
    return Finding("road", "trigger", OK, typical, f"the channels' typical lag {1e3 * typical:.1f} ms")


def check_channels(
    channels: Sequence[Channel], assumed_from_data: bool = False, units: dict[str, tuple[str, str]] | None = None
) -> Checks:
    """Every registered fault's check and the noise check on every channel (in the channels' order), and where its
    unit came from (`units`: channel -> (unit, origin); None: a format whose units are SI by definition)."""
    channels = tuple(channels)
    findings = []
    for ch in channels:
        if units and ch.name in units:
            findings.append(unit_finding(ch.name, *units[ch.name]))
        for fault in FAULTS.values():
            found = fault.check(ch, channels)
            if found is not None:
                findings.append(found)
        findings.append(noise_finding(ch, assumed_from_data))
    trigger = trigger_finding(channels)
    return Checks(tuple(findings) + (() if trigger is None else (trigger,)))


def check_runs(tasks: Sequence[Task], views: Sequence[Sequence[Channel]] | None = None) -> Checks:
    """The checks of every run (several: each finding tagged with its run's file); `views`: each run's channel views
    when the caller has them already (`Task.channel_views`: a simulation of the configured model each)."""
    each = [None] * len(tasks) if views is None else views
    found = [check_task(t, views=v) for t, v in zip(tasks, each, strict=True)]
    merged = found[0]
    for t, more in zip(tasks[1:], found[1:], strict=True):
        merged = merged.merged(more, tasks[0].data_file, t.data_file)
    return merged


def check_task(
    task: Task, reference: dict[str, NDArray] | None = None, views: Sequence[Channel] | None = None
) -> Checks:
    """The checks of a task's measured run (`reference`: its data, default the measured channels; `views`: its
    channel views of the measured channels, when the caller has them already)."""
    from_data = task.sigma_source.startswith("estimated")
    return check_channels(task.channel_views(reference) if views is None else views, from_data, task.units)
