"""The `design:` section of a car's config: the limits within which `vehid design` plans the test.

Every range is optional: a variable without a range keeps its configured value (it is not designed). Units: speeds
in km/h, heights and lengths in m, durations in s. The checks here are those of the section alone; the ones
against the rest of the config (a bump to design, a criterion's parameter among the unknowns, sensor families the
objective uses) are in `vehid_cli.design.check_design`.
"""

from __future__ import annotations

import re
from typing import Annotated, NamedTuple

from pydantic import Field, model_validator

from .common import BumpShape, Seed, _KeyedError, _Section, int_in, within
from .sensors import SensorSpec

Speed = within(0, 1000, low_open=True)  # km/h, as road.speed_kmh
BumpLength = within(1e-4, 100, low_open=True)  # m, as road.bump.length
Duration = within(0, 1e5, low_open=True)  # s, as simulation.duration
CRITERIA = ("nre", "d_optimal", "worst")  # worst: the largest bound; worst:<param>: that parameter's
CRITERION = re.compile(r"^(nre|d_optimal|worst)(?::(\S+))?$")


class DesignVariable(NamedTuple):
    """One variable of a test a system designs through its config (the rigs): the config key it is written to, its
    range, its unit, and keys the written value replaces (removed from the config)."""

    key: str
    lower: float
    upper: float
    unit: str
    replaces: tuple[str, ...] = ()


def check_criterion(criterion: str) -> None:
    """Refuse an unknown design.criterion (keyed)."""
    if CRITERION.match(criterion) is None:
        raise _KeyedError(
            "design.criterion", f"unknown criterion '{criterion}' (known: nre, d_optimal, worst, worst:<param>)"
        )


def check_range(key: str, pair: tuple[float, float] | None, unit: str) -> None:
    """Refuse a design range whose min is above its max (keyed)."""
    if pair is not None and not pair[0] <= pair[1]:
        raise _KeyedError(key, f"empty range: min {pair[0]:g} {unit} is above max {pair[1]:g} {unit}")


class DesignHeights(_Section):
    """Bump heights: the highest corner at `max`, every corner at least `min`; the design variables are the ratio
    of the two sides (b2 over b1) and, with `per_axle`, of the rear axle over the front."""

    max: within(-1, 1) = Field(description="highest allowed bump height [m]")
    min: within(0, 1) = Field(0.0, description="lowest allowed bump height under any corner [m] (0: that side flat)")
    per_axle: bool = Field(
        False,
        description="also design the rear axle's heights apart from the front's (two bumps, or a rig); false: the "
        "rear tyres meet the front's bump, as on a road",
    )

    @model_validator(mode="after")
    def _limits(self) -> DesignHeights:
        if not self.max > 0:
            raise _KeyedError("design.heights.max", f"the highest bump must be above 0 m, got {self.max:g}")
        if self.min > self.max:
            raise _KeyedError("design.heights.min", f"min {self.min:g} m is above max {self.max:g} m")
        return self


class DesignSensors(_Section):
    """Choose `count` sensors among `candidates` (specs as in `layout`): every subset when there are few, else a
    greedy choice improved by exchanges."""

    count: int_in(-1000, 1000) = Field(description="how many sensors to mount")
    candidates: tuple[SensorSpec, ...] = Field(description="the allowed mounting points (sensor specs of `layout`)")

    @model_validator(mode="after")
    def _count(self) -> DesignSensors:
        if self.count < 1:
            raise _KeyedError(
                "design.sensors.count", f"zero sensors measure nothing: count must be >= 1, got {self.count}"
            )
        if not self.candidates:
            raise _KeyedError("design.sensors.candidates", "no candidate mounting points")
        if self.count > len(self.candidates):
            raise _KeyedError(
                "design.sensors.count", f"{self.count} sensors but only {len(self.candidates)} candidates"
            )
        names = [c.name for c in self.candidates]
        for i, name in enumerate(names):
            if name in names[:i]:
                raise _KeyedError(f"design.sensors.candidates.{i}.name", f"sensor name '{name}' is used twice")
        return self


class DesignSearch(_Section):
    """The global optimizer (scipy differential_evolution, deferred updating: bit-identical for any job count)."""

    population: int_in(4, 10_000) = Field(15, description="candidates per generation")
    iterations: int_in(1, 100_000) = Field(25, description="generations at most")
    seed: Seed = Field(2015, description="seed of the optimizer's stream")
    grid: Annotated[int, Field(ge=3, le=201)] = Field(
        21, description="points per variable of the figures' sweeps and of the single-variable changes"
    )


CRITERION_HELP = (
    "nre: the bound on the per-run NRE RMS; d_optimal: the largest log det of the Fisher information; worst: the "
    "largest per-parameter bound; worst:<param>: that parameter's bound"
)


class DesignGoal:
    """What 'best' means for a design section (the car's, a rig's), mixed into it: its `criterion` field read apart."""

    @property
    def criterion_kind(self) -> str:
        """nre, d_optimal or worst."""
        return CRITERION.match(self.criterion).group(1)

    @property
    def criterion_parameter(self) -> str | None:
        """The parameter of worst:<param> (None: every unknown)."""
        return CRITERION.match(self.criterion).group(2)


class Design(DesignGoal, _Section):
    """Limits of the test `vehid design` plans, and what 'best' means."""

    speed_kmh: tuple[Speed, Speed] | None = Field(None, description="forward speed range [km/h]")
    heights: DesignHeights | None = None
    shapes: tuple[BumpShape, ...] | None = Field(None, description="bump shapes to choose from")
    length: tuple[BumpLength, BumpLength] | None = Field(None, description="bump (ramp) length range [m]")
    duration: tuple[Duration, Duration] | None = Field(None, description="record length range [s]")
    sensors: DesignSensors | None = None
    criterion: str = Field("nre", description=CRITERION_HELP)
    search: DesignSearch = DesignSearch()

    @model_validator(mode="after")
    def _limits(self) -> Design:
        check_range("design.speed_kmh", self.speed_kmh, "km/h")
        check_range("design.length", self.length, "m")
        check_range("design.duration", self.duration, "s")
        if self.shapes is not None and not self.shapes:
            raise _KeyedError("design.shapes", "no bump shape to choose from")
        check_criterion(self.criterion)
        return self
