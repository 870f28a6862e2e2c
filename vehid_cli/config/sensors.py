"""One sensor of a car's layout as a config gives it (`layout:`, `design.sensors.candidates`)."""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from ..models.sensors import Sensor
from .common import _Section, within


class SensorSpec(_Section):
    """One sensor of the layout: a body sensor at (x, y) from a reference point, or a wheel or deflection sensor at
    a corner."""

    name: str = Field(description="channel name (the key of data.channels; the column `vehid simulate` writes)")
    kind: Literal["body_acc", "body_disp", "wheel_acc", "wheel_disp", "deflection"] = Field(
        description="body_acc, body_disp: vertical motion of a body point; wheel_acc, wheel_disp: a wheel's hop; "
        "deflection: suspension deflection at a corner (body point above it minus the wheel, extension +)"
    )
    x: within(-100, 100) | None = Field(None, description="body sensors: forward of `origin` [m]")
    y: within(-100, 100) | None = Field(
        None, description="body sensors: toward side 1 (corners 1, 4) from `origin` [m]"
    )
    origin: Literal["cg", "corner1", "corner2", "corner3", "corner4", "front_axle", "rear_axle"] | None = Field(
        None,
        description="body sensors: the point x, y are measured from (default cg); a corner or axle centre stays "
        "put when the CG (a1, b1) is identified",
    )
    corner: Annotated[int, Field(ge=1, le=4)] | None = Field(None, description="wheel and deflection sensors: 1..4")
    sigma: within(0, 1e4, low_open=True) | None = Field(
        None, description="this channel's noise standard deviation [m/s² or m]"
    )

    @model_validator(mode="after")
    def _where(self) -> SensorSpec:
        if self.kind.startswith("body"):
            if self.corner is not None:
                raise ValueError(f"a {self.kind} sensor is placed by x, y (and origin), not by 'corner'")
        else:
            if self.corner is None:
                raise ValueError(f"a {self.kind} sensor needs its 'corner' (1..4)")
            given = [k for k in ("x", "y", "origin") if getattr(self, k) is not None]
            if given:
                raise ValueError(f"a {self.kind} sensor sits at its corner: remove {', '.join(given)}")
        return self

    def sensor(self) -> Sensor:
        return Sensor(
            name=self.name, kind=self.kind, x=self.x or 0.0, y=self.y or 0.0, origin=self.origin or "cg",
            corner=self.corner or 0,
        )  # fmt: skip
