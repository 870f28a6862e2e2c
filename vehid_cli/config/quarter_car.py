"""The quarter car's config (`system: quarter_car`): a body mass on a spring and a damper over a wheel mass on a tyre
spring and damper, driven by a road plate (column road1) and optionally an actuator force between body and wheel."""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal

from pydantic import Field

from ..core.units import Unit
from .common import _KeyedError, _Section, within
from .lumped import LumpedConfig, RigIdentify, RigSensor

# Physical ranges (kg, N/m, N s/m): from a bench-top rig to a truck's corner, finite numerics on any grid.
RANGES = {
    "ms": (1e-3, 1e5),
    "mu": (1e-4, 1e4),
    "ks": (1e-2, 1e9),
    "kt": (1e-2, 1e10),
    "cs": (0.0, 1e7),
    "ct": (0.0, 1e7),
    "force_gain": (-1e3, 1e3),
}  # fmt: skip
PARAMETERS = tuple(RANGES)


class QuarterCar(_Section):
    """The quarter car [SI]: ms, mu [kg], ks, kt [N/m], cs, ct [N s/m]."""

    ms: Annotated[within(*RANGES["ms"]), Unit("kg")] = Field(description="sprung (body) mass [kg]")
    mu: Annotated[within(*RANGES["mu"]), Unit("kg")] = Field(description="unsprung (wheel) mass [kg]")
    ks: Annotated[within(*RANGES["ks"]), Unit("N/m")] = Field(description="suspension stiffness [N/m]")
    kt: Annotated[within(*RANGES["kt"]), Unit("N/m")] = Field(description="tyre stiffness [N/m]")
    cs: Annotated[within(*RANGES["cs"]), Unit("N s/m")] = Field(description="suspension damping [N s/m]")
    ct: Annotated[within(*RANGES["ct"]), Unit("N s/m")] = Field(0.0, description="tyre damping [N s/m]")
    force_gain: Annotated[within(*RANGES["force_gain"]), Unit("-")] = Field(
        1.0, description="the actuator's force per unit of the recorded force (-1: the rig's sign is opposite ours)"
    )

    def values(self) -> dict[str, float]:
        return {n: float(getattr(self, n)) for n in PARAMETERS}


class QuarterCarIdentify(RigIdentify):
    unknowns: tuple[str, ...] = ("ms", "ks", "cs")


class QuarterCarConfig(LumpedConfig):
    """A quarter-car rig: the car, its inputs, sensors, noise, measured runs and what to identify."""

    section: ClassVar[str] = "quarter_car"
    inputs: ClassVar[tuple[str, ...]] = ("road1",)
    system: Literal["quarter_car"]
    quarter_car: QuarterCar
    identify: QuarterCarIdentify = QuarterCarIdentify()

    def ranges(self) -> dict[str, tuple[float, float]]:
        return dict(RANGES)

    def check_sensor(self, index: int, sensor: RigSensor) -> None:
        given = [k for k in ("x", "origin", "corner") if getattr(sensor, k) is not None]
        if given:
            raise _KeyedError(f"layout.{index}", f"a quarter car's sensors have no place: remove {', '.join(given)}")
