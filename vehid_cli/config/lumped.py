"""What the configs of the lumped linear rigs share (the quarter car, the half car): the rig's inputs (a road plate
driven by a chirp, bumps or a random road, or measured; an optional actuator force), the sensors (`layout:`), the
noise, the measured runs and the identification. A rig's own section module (`quarter_car`, `half_car`) adds its
parameters, its sensor placement and its input names."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, ClassVar, Literal

from pydantic import Field, model_validator

from ..core.errors import InputError
from ..core.units import SI_FACTORS, UNITS
from .common import (
    BumpShape,
    ConfigEdit,
    IdentifyCommon,
    NonNeg,
    Pos,
    SystemConfig,
    _did_you_mean,
    _KeyedError,
    _Section,
    within,
)
from .design import CRITERION_HELP, DesignGoal, DesignSearch, DesignVariable, check_criterion, check_range
from .vehicle import SIMULATION_SAMPLES, Noise, RandomRoad

Frequency = within(1e-4, 1e5)
KINDS = ("body_acc", "body_disp", "wheel_acc", "wheel_disp", "deflection")
FAMILY = {"body_acc": "acc", "wheel_acc": "acc", "body_disp": "disp", "wheel_disp": "disp", "deflection": "disp"}


class Chirp(_Section):
    """A linear sine sweep from f0 to f1 over `duration` from `start`, faded in and out over `fade` [s]."""

    f0: Frequency = Field(0.5, description="start frequency [Hz]")
    f1: Frequency = Field(20.0, description="end frequency [Hz]")
    amplitude: within(0, 1e7, low_open=True) = Field(description="amplitude [m for the road, N for the force]")
    start: within(0, 1e6) = Field(0.0, description="time the sweep starts [s]")
    duration: within(0, 1e6, low_open=True) | None = Field(
        None, description="sweep length [s] (default: to the end of the simulation)"
    )
    fade: within(0, 100) = Field(0.2, description="half-cosine fade in and out [s]")


class RigBump(_Section):
    """A bump met at the road speed (the rear wheel of a half car meets it wheelbase/speed later)."""

    shape: BumpShape = "cosine_step"
    length: within(1e-4, 100, low_open=True) = Field(0.1, description="ramp or bump length [m]")
    plateau: within(0, 1000) = Field(0.0, description="flat top of a trapezoid [m]")
    height: within(-1, 1) = Field(description="bump height [m]")
    start_time: within(0, 1e6) = Field(0.1, description="time the (front) wheel meets it [s]")


class RigRoad(_Section):
    """The rig's inputs: the road under the wheel(s) and an actuator force between body and wheel."""

    input: Literal["config", "measured", "track"] = Field(
        "config",
        description="config: the chirp, bump and random road below; measured: the data file's road columns; track: "
        "its column road1, which the later wheels meet wheelbase/speed later",
    )
    actuator_force: Literal["none", "config", "measured"] = Field(
        "none",
        description="none; config: the `force` chirp; measured: the data file's column `force` [N], pushing the body "
        "up and the wheel down",
    )
    speed: within(0, 300, low_open=True) | None = Field(None, description="road speed [m/s] (bump, random, delay)")
    speed_kmh: within(0, 1000, low_open=True) | None = Field(None, description="road speed [km/h]")
    chirp: Chirp | None = Field(None, description="a road-plate sweep [m]")
    bump: RigBump | None = None
    random: RandomRoad | None = None
    force: Chirp | None = Field(None, description="the actuator force sweep [N] (actuator_force: config)")

    @model_validator(mode="after")
    def _sources(self) -> RigRoad:
        if self.speed is not None and self.speed_kmh is not None:
            raise ValueError("give either 'speed' or 'speed_kmh', not both")
        if (self.bump is not None or self.random is not None) and self.V is None:
            raise _KeyedError("road.speed", "a bump or a random road is met at a speed: give 'speed' [m/s]")
        if self.actuator_force == "config" and self.force is None:
            raise _KeyedError("road.force", "actuator_force 'config' drives the `force` chirp: give road.force")
        return self

    @property
    def V(self) -> float | None:
        """Road speed [m/s], None when not given."""
        return self.speed if self.speed is not None else None if self.speed_kmh is None else self.speed_kmh / 3.6

    @property
    def configured(self) -> bool:
        return self.chirp is not None or self.bump is not None or self.random is not None


class RigSimulation(_Section):
    """The simulated record: its length and time step (the exact first-order-hold path, no integrator to choose)."""

    duration: within(0, 1e5, low_open=True) = Field(10.0, description="simulated time [s]")
    dt: within(1e-7, 1) = Field(0.002, description="time step [s]")

    @model_validator(mode="after")
    def _grid(self) -> RigSimulation:
        if self.dt * 2 > self.duration:
            raise ValueError(f"dt = {self.dt:g} s leaves fewer than 3 samples in duration = {self.duration:g} s")
        if self.duration / self.dt > SIMULATION_SAMPLES:
            raise ValueError(f"duration/dt = {self.duration / self.dt:.3g} samples is more than {SIMULATION_SAMPLES:,}")
        return self


class RigSensor(_Section):
    """One sensor: what it measures and (on a half car) where."""

    name: str = Field(description="channel name (a data column; the column `vehid simulate` writes)")
    kind: Literal["body_acc", "body_disp", "wheel_acc", "wheel_disp", "deflection"] = Field(
        description="body_acc, body_disp: the body (at x on a half car); wheel_acc, wheel_disp: a wheel; deflection: "
        "body above the wheel minus the wheel (extension +)"
    )
    x: within(-100, 100) | None = Field(None, description="half car, body sensors: forward of `origin` [m]")
    origin: Literal["cg", "front_axle", "rear_axle"] | None = Field(
        None, description="half car, body sensors: the point x is measured from (default cg)"
    )
    corner: Annotated[int, Field(ge=1, le=2)] | None = Field(
        None, description="half car, wheel and deflection sensors: 1 front, 2 rear"
    )
    sigma: within(0, 1e4, low_open=True) | None = Field(None, description="noise standard deviation [m/s² or m]")

    @property
    def family(self) -> str:
        return FAMILY[self.kind]


class RigData(_Section):
    """Measured runs: which column is which channel, in which unit."""

    files: tuple[str, ...] = Field((), description="runs identified jointly (relative to the config); --data wins")
    channels: dict[str, str] = Field({}, description="our name (a sensor, an input) -> the name in the file")
    units: dict[str, str] = Field({}, description="our name (or a family, acc or disp) -> its unit in the file")
    invert: tuple[str, ...] = Field((), description="channels (sensors or inputs) whose sign the chain inverts")
    time: str | None = Field(None, description="the time column (default t or time)")
    time_unit: str = Field("s", description="unit of a numeric time column")
    window: tuple[NonNeg, Pos] | None = Field(None, description="use only start <= t < stop [s]")
    rate: Pos | None = Field(None, description="rate of the common grid [Hz] (default: the fastest channel's)")
    offsets: Literal["none", "identify"] = Field(
        "none",
        description="sensor offsets (a potentiometer's zero, an accelerometer's bias): none; identify (one nuisance "
        "offset per channel and run, profiled out of the fit and the bound)",
    )

    @model_validator(mode="after")
    def _checks(self) -> RigData:
        for ours, unit in self.units.items():
            if unit not in SI_FACTORS:
                raise _KeyedError(f"data.units.{ours}", f"unknown unit '{unit}'{_did_you_mean(unit, SI_FACTORS)}")
        if self.time_unit not in UNITS["time"]:
            raise _KeyedError("data.time_unit", f"unknown time unit '{self.time_unit}'")
        if self.window is not None and not self.window[0] < self.window[1]:
            raise _KeyedError("data.window", f"start {self.window[0]:g} s must be before stop {self.window[1]:g} s")
        return self


class RigIdentify(IdentifyCommon):
    """What to identify and how; the objective is the weighted least squares of every channel."""

    objective: Literal["wls"] = "wls"


class RigDesign(DesignGoal, _Section):
    """Limits of the rig's test `vehid design` plans: the road chirp's band (its start and end frequencies, each
    anywhere in the band: up or down sweeps) and amplitude, the actuator force chirp's amplitude, the bump's speed
    and height. A variable without a range keeps its configured value; each needs its input configured."""

    band: tuple[Frequency, Frequency] | None = Field(
        (0.5, 30.0), description="road.chirp's f0 and f1 range [Hz] (null: the configured band)"
    )
    amplitude: tuple[within(0, 1e7, low_open=True), within(0, 1e7, low_open=True)] | None = Field(
        None, description="road.chirp's amplitude range [m] (at most the rig's stroke)"
    )
    force_amplitude: tuple[within(0, 1e7, low_open=True), within(0, 1e7, low_open=True)] | None = Field(
        None, description="road.force's amplitude range [N] (actuator_force: config)"
    )
    bump_speed_kmh: tuple[within(0, 1000, low_open=True), within(0, 1000, low_open=True)] | None = Field(
        None, description="the speed the bump is met at [km/h]"
    )
    bump_height: tuple[within(-1, 1), within(-1, 1)] | None = Field(None, description="road.bump's height range [m]")
    criterion: str = Field("nre", description=CRITERION_HELP)
    search: DesignSearch = DesignSearch()

    @model_validator(mode="after")
    def _limits(self) -> RigDesign:
        for key, unit in (("band", "Hz"), ("amplitude", "m"), ("force_amplitude", "N"), ("bump_speed_kmh", "km/h"),
                          ("bump_height", "m")):  # fmt: skip
            check_range(f"design.{key}", getattr(self, key), unit)
        check_criterion(self.criterion)
        return self


class LumpedConfig(SystemConfig):
    """Base of a lumped rig's config: the subclass sets `section` (its parameters' key), `inputs` (the road columns)
    and adds that section; `values()` of the section gives the parameters."""

    section: ClassVar[str]
    inputs: ClassVar[tuple[str, ...]]  # road columns, front first
    road: RigRoad = RigRoad()
    simulation: RigSimulation = RigSimulation()
    layout: Annotated[tuple[RigSensor, ...], Field(min_length=1)]
    noise: Noise = Noise()
    data: RigData = RigData()
    identify: RigIdentify
    design: RigDesign | None = None

    def design_variables(self) -> tuple[DesignVariable, ...]:
        """The variables of the test `vehid design` plans (`design:`), each with the config key it is written to;
        keyed error when a range is given for an input the rig does not have configured."""
        d, road = self.design, self.road
        if d is None:
            raise self._refused("design", "no 'design' section: give the limits of the test to plan (README)")
        if self.data.files:
            raise self._refused("data.files", "vehid design plans a simulated test: remove data.files")
        out = []
        if d.band is not None and road.chirp is not None:
            out += [DesignVariable("road.chirp.f0", *d.band, "Hz"), DesignVariable("road.chirp.f1", *d.band, "Hz")]
        if d.amplitude is not None:
            if road.chirp is None:
                raise self._refused("design.amplitude", "the road chirp's amplitude needs road.chirp")
            out.append(DesignVariable("road.chirp.amplitude", *d.amplitude, "m"))
        if d.force_amplitude is not None:
            if road.actuator_force != "config":
                raise self._refused(
                    "design.force_amplitude", "the force chirp's amplitude needs actuator_force: config"
                )
            out.append(DesignVariable("road.force.amplitude", *d.force_amplitude, "N"))
        for key, pair, target, unit in (("bump_speed_kmh", d.bump_speed_kmh, "road.speed_kmh", "km/h"),
                                        ("bump_height", d.bump_height, "road.bump.height", "m")):  # fmt: skip
            if pair is not None:
                if road.bump is None:
                    raise self._refused(f"design.{key}", "the bump's speed and height need road.bump")
                out.append(DesignVariable(target, *pair, unit, ("road.speed",) if key == "bump_speed_kmh" else ()))
        if road.input != "config" and any(v.key.startswith("road.chirp") or v.key.startswith("road.bump")
                                          for v in out):  # fmt: skip
            raise self._refused("road.input", "vehid design plans the configured road: road.input must be config")
        if not out:
            raise self._refused("design", "nothing to design: give a range (band, amplitude, force_amplitude, "
                              "bump_speed_kmh, bump_height) for an input the rig has")  # fmt: skip
        return tuple(out)

    def _refused(self, key: str, message: str) -> InputError:
        return InputError(message, source=self.source, key=key)

    def parameter_values(self) -> dict[str, float]:
        return getattr(self, self.section).values()

    def ranges(self) -> dict[str, tuple[float, float]]:
        """Each parameter's physical range."""
        return {}

    @property
    def input_names(self) -> tuple[str, ...]:
        """The input columns of a data file: the road, then `force` with a measured or configured actuator."""
        return self.inputs + (("force",) if self.road.actuator_force != "none" else ())

    def delays(self) -> tuple[float, ...]:
        """When each wheel meets the road after the first [s] (the road's inputs in order)."""
        return (0.0,) * len(self.inputs)

    def check_sensor(self, index: int, sensor: RigSensor) -> None:
        """Refuse a sensor the rig cannot place (the subclass knows where its sensors go)."""

    @model_validator(mode="after")
    def _common(self) -> LumpedConfig:
        names = [s.name for s in self.layout]
        for i, sensor in enumerate(self.layout):
            if sensor.name in names[:i]:
                raise _KeyedError(f"layout.{i}.name", f"sensor name '{sensor.name}' is used twice")
            if sensor.name in ("t", "force", *self.inputs):
                raise _KeyedError(f"layout.{i}.name", f"'{sensor.name}' names an input; choose another sensor name")
            self.check_sensor(i, sensor)
        if self.road.input == "config" and not self.road.configured and not self.data.files:
            raise _KeyedError("road", "input 'config' needs a 'chirp', a 'bump' or a 'random' road")
        known = (*names, *self.inputs, "force")
        for key, table in (("channels", self.data.channels), ("units", self.data.units)):
            for name in table:
                if name not in known and not (key == "units" and name in ("acc", "disp")):
                    raise _KeyedError(f"data.{key}.{name}", f"'{name}' is not a channel (known: {', '.join(known)})")
        for name in self.data.invert:
            if name not in known:
                raise _KeyedError("data.invert", f"'{name}' is not a channel (known: {', '.join(known)})")
        values, ident = self.parameter_values(), self.identify
        for name in ident.unknowns:
            if name not in values:
                raise _KeyedError("identify.unknowns", f"'{name}' is not a parameter{_did_you_mean(name, values)} "
                                  f"(known: {', '.join(values)})")  # fmt: skip
        ident.check_names()
        box = self.search_box()
        ident.check_box(values, box, self.ranges().get)
        for name, (lo, _) in box.items():
            if lo <= 0 and self.ranges().get(name, (1, 1))[0] > 0:
                raise _KeyedError(f"identify.limits.{name}", f"'{name}' must stay positive; got lower limit {lo:g}")
        return self

    def search_box(self) -> dict[str, tuple[float, float]]:
        """Search range of each unknown [SI]: 'limits' where given, else 'bounds' x configured value."""
        return self.identify.box(self.parameter_values())

    def edits_for(self, values: Mapping[str, float]) -> list[ConfigEdit]:
        """`<section>.<name>` for the rig's parameters; an effect's parameter (`vehid diagnose` fitted it to the
        struts) has no key in a rig's config, which describes a linear rig: InputError naming it."""
        section = getattr(self, self.section)
        other = [n for n in values if n not in type(section).model_fields]
        if other:
            raise InputError(f"--save-config: a {self.section} config has no key for {', '.join(other)} (its model "
                             "is linear; the effects stay in the report)", source=self.source)  # fmt: skip
        return [ConfigEdit(f"{self.section}.{n}", float(v), n) for n, v in values.items()]

    def resolved(self, path: Path) -> LumpedConfig:
        if not self.data.files:
            return self
        files = tuple(f if Path(f).is_absolute() else (path.parent / f).as_posix() for f in self.data.files)
        return self._relocated({"data": self.data.model_copy(update={"files": files})})

    def data_runs(self) -> tuple[str, ...]:
        return tuple(self.data.files)
