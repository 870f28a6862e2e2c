"""The half car's config (`system: half_car`): the pitch plane of a car, a body (bounce and pitch) on a front and a
rear suspension over two wheels, driven by road1 (front) and road2 (rear), or one track the rear wheel meets
wheelbase/speed later."""

from __future__ import annotations

from typing import Annotated, ClassVar, Literal

from pydantic import Field, model_validator

from ..core.units import Unit
from .common import _KeyedError, _Section, within
from .lumped import LumpedConfig, RigIdentify, RigSensor
from .vehicle import RANGES as CAR_RANGES

PARAMETERS = ("m", "Iy", "mf", "mr", "a1", "wheelbase", "kf", "kr", "ktf", "ktr", "cf", "cr")
RANGES = {n: CAR_RANGES[n] for n in PARAMETERS}


class HalfCar(_Section):
    """The pitch plane [SI]: m [kg], Iy [kg m²], mf, mr [kg], a1, wheelbase [m], kf, kr, ktf, ktr [N/m], cf, cr
    [N s/m]. The wheelbase stays fixed when a1 (the CG) is identified."""

    m: Annotated[within(*RANGES["m"]), Unit("kg")] = Field(description="body mass [kg]")
    Iy: Annotated[within(*RANGES["Iy"]), Unit("kg m²")] = Field(description="pitch moment of inertia [kg m²]")
    mf: Annotated[within(*RANGES["mf"]), Unit("kg")] = Field(description="front unsprung mass [kg]")
    mr: Annotated[within(*RANGES["mr"]), Unit("kg")] = Field(description="rear unsprung mass [kg]")
    a1: Annotated[within(*RANGES["a1"]), Unit("m")] = Field(description="CG to front axle [m]")
    wheelbase: Annotated[within(*RANGES["wheelbase"]), Unit("m")] = Field(description="front to rear axle [m]")
    kf: Annotated[within(*RANGES["kf"]), Unit("N/m")] = Field(description="front suspension stiffness [N/m]")
    kr: Annotated[within(*RANGES["kr"]), Unit("N/m")] = Field(description="rear suspension stiffness [N/m]")
    ktf: Annotated[within(*RANGES["ktf"]), Unit("N/m")] = Field(description="front tyre stiffness [N/m]")
    ktr: Annotated[within(*RANGES["ktr"]), Unit("N/m")] = Field(description="rear tyre stiffness [N/m]")
    cf: Annotated[within(*RANGES["cf"]), Unit("N s/m")] = Field(description="front suspension damping [N s/m]")
    cr: Annotated[within(*RANGES["cr"]), Unit("N s/m")] = Field(description="rear suspension damping [N s/m]")

    @model_validator(mode="after")
    def _cg(self) -> HalfCar:
        if not self.a1 < self.wheelbase:
            raise _KeyedError("half_car.a1", f"a1 = {self.a1:g} m puts the CG behind the rear axle "
                              f"(wheelbase {self.wheelbase:g} m): expected 0 < a1 < wheelbase")  # fmt: skip
        return self

    def values(self) -> dict[str, float]:
        return {n: float(getattr(self, n)) for n in PARAMETERS}


class HalfCarIdentify(RigIdentify):
    unknowns: tuple[str, ...] = ("m", "Iy", "a1", "kf", "kr", "cf", "cr")


class HalfCarConfig(LumpedConfig):
    """A car's pitch plane on its road: the car, its inputs, sensors, noise, measured runs and what to identify."""

    section: ClassVar[str] = "half_car"
    inputs: ClassVar[tuple[str, ...]] = ("road1", "road2")
    system: Literal["half_car"]
    half_car: HalfCar
    identify: HalfCarIdentify = HalfCarIdentify()

    def ranges(self) -> dict[str, tuple[float, float]]:
        return dict(RANGES)

    def delays(self) -> tuple[float, ...]:
        V = self.road.V
        return (0.0, 0.0 if V is None else self.half_car.wheelbase / V)

    def check_sensor(self, index: int, sensor: RigSensor) -> None:
        if sensor.kind.startswith("body"):
            if sensor.corner is not None:
                raise _KeyedError(f"layout.{index}", f"a {sensor.kind} sensor is placed by x (and origin), not corner")
        elif sensor.corner is None or sensor.x is not None or sensor.origin is not None:
            raise _KeyedError(f"layout.{index}", f"a {sensor.kind} sensor sits at its corner: give corner (1 front, "
                              "2 rear) and no x or origin")  # fmt: skip

    @model_validator(mode="after")
    def _half(self) -> HalfCarConfig:
        if self.road.actuator_force != "none":
            raise _KeyedError("road.actuator_force", "the half car has no actuator force (a quarter car has)")
        if self.road.input == "track" and self.road.V is None:
            raise _KeyedError("road.speed", "input 'track' delays the rear by wheelbase/speed: give 'speed'")
        if "wheelbase" in self.identify.unknowns:
            raise _KeyedError("identify.unknowns", "the wheelbase is measured, not identified: identify a1 (the CG)")
        lo, hi = self.search_box().get("a1", (0.0, 0.0))
        if "a1" in self.identify.unknowns and not 0 < lo < hi < self.half_car.wheelbase:
            raise _KeyedError("identify.bounds", f"the search range [{lo:g}, {hi:g}] m of a1 leaves the wheelbase")
        return self
