"""The full car's config: the vehicle, the road, the time grid, the sensors, the noise, the identification."""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, model_validator

from ..core.errors import InputError
from ..core.units import SI_FACTORS, UNITS, Unit
from ..models.effects import LIBRARY, bound_violation
from ..models.fullcar import VEHICLE_PARAMETERS
from ..models.sensors import FAMILY, UNIT, Layout, corner_layout
from .common import (
    BumpShape,
    ConfigEdit,
    Finite,
    IdentifyCommon,
    NonNeg,
    Pos,
    SystemConfig,
    _did_you_mean,
    _KeyedError,
    _Section,
    within,
)
from .design import Design
from .sensors import SensorSpec

# The car's parameters: positive (kR, cf and cr may be 0) and within broad physical bounds, from a go-kart to a
# heavy truck, so that every frequency and time constant of the model stays finite on any time grid.
RANGES = {
    "m": (0.1, 1e6),
    "mf": (0.01, 1e5),
    "Ix": (0.01, 1e8),
    "a1": (1e-3, 100),
    "kf": (1, 1e10),
    "kR": (0, 1e10),
    "cf": (0, 1e8),
}  # fmt: skip  (kg, kg m², m, N/m, N m/rad, N s/m)
RANGES.update(mr=RANGES["mf"], Iy=RANGES["Ix"], kr=RANGES["kf"], ktf=RANGES["kf"], ktr=RANGES["kf"], cr=RANGES["cf"])
RANGES.update({n: RANGES["a1"] for n in ("a2", "b1", "b2", "wheelbase", "track")})
# Each parameter's type carries its SI unit (core.units.Unit): tables, JSON and results files read it from here.
Mass = Annotated[within(*RANGES["m"]), Unit("kg")]
Unsprung = Annotated[within(*RANGES["mf"]), Unit("kg")]
Inertia = Annotated[within(*RANGES["Ix"]), Unit("kg m²")]
Length = Annotated[within(*RANGES["a1"]), Unit("m")]
Stiffness = Annotated[within(*RANGES["kf"]), Unit("N/m")]
RollStiffness = Annotated[within(*RANGES["kR"]), Unit("N m/rad")]
Damping = Annotated[within(*RANGES["cf"]), Unit("N s/m")]
Height = within(-1, 1)  # m, a bump under one corner
SIMULATION_SAMPLES = 1_000_000  # samples of a simulated record at most (1000 s at 1 kHz)
SIMULATION_STEPS = 20_000_000  # integration steps (samples x substeps) of one simulation at most


def _parameter_range(name: str) -> tuple[float, float] | None:
    """The physical range of an identifiable value: a car's parameter (RANGES) or a declared effect's."""
    if "." in name:
        effect, param = name.split(".", 1)
        p = LIBRARY[effect].param(param)
        return (p.lower, p.upper)
    return RANGES.get(name)


class Vehicle(_Section):
    """The 7-DOF full car (Gökdağ Fig. 1). SI units: kg, kg m², m, N/m, N m/rad (kR), N s/m."""

    m: Mass = Field(description="sprung (body) mass [kg]")
    mf: Unsprung = Field(description="front unsprung mass, each [kg]")
    mr: Unsprung = Field(description="rear unsprung mass, each [kg]")
    Ix: Inertia = Field(description="roll moment of inertia [kg m²]")
    Iy: Inertia = Field(description="pitch moment of inertia [kg m²]")
    a1: Length = Field(description="CG to front axle [m]")
    a2: Length | None = Field(None, description="CG to rear axle [m]; or give wheelbase")
    b1: Length = Field(description="CG to side-1 wheels (corners 1, 4) [m]")
    b2: Length | None = Field(None, description="CG to side-2 wheels (corners 2, 3) [m]; or give track")
    wheelbase: Length | None = Field(None, description="a1 + a2 [m], alternative to a2")
    track: Length | None = Field(None, description="b1 + b2 [m], alternative to b2")
    kf: Stiffness = Field(description="front suspension stiffness [N/m]")
    kr: Stiffness = Field(description="rear suspension stiffness [N/m]")
    ktf: Stiffness = Field(description="front tyre stiffness [N/m]")
    ktr: Stiffness = Field(description="rear tyre stiffness [N/m]")
    kR: RollStiffness = Field(0.0, description="front anti-roll bar stiffness [N m/rad]")
    cf: Damping = Field(description="front suspension damping [N s/m]")
    cr: Damping = Field(description="rear suspension damping [N s/m]")
    effects: dict[str, dict[str, Finite] | None] | None = Field(
        None,
        description="nonlinear effects beside the linear car: effect name -> its parameters "
        "(vehid_cli/models/effects/, one module each; missing parameters at their defaults); "
        "needs simulation.integrator rk4 or newmark",
    )

    @model_validator(mode="after")
    def _effects(self) -> Vehicle:
        for name, params in (self.effects or {}).items():
            key = f"vehicle.effects.{name}"
            if name not in LIBRARY:
                hint = _did_you_mean(name, LIBRARY)
                known = "" if hint else f" (known: {', '.join(LIBRARY)})"
                raise _KeyedError(key, f"unknown effect '{name}'{hint}{known}")
            effect = LIBRARY[name]
            for pname, value in (params or {}).items():
                if pname not in effect.names():
                    hint = _did_you_mean(pname, effect.names())
                    if f"{pname}_f" in effect.names():
                        hint = f"; it is per axle: give '{pname}_f' and '{pname}_r'"
                    known = "" if hint else f" (known: {', '.join(effect.names())})"
                    raise _KeyedError(f"{key}.{pname}", f"'{pname}' is not a parameter of {name}{hint}{known}")
                why = bound_violation(name, pname, value)
                if why is not None:
                    raise _KeyedError(f"{key}.{pname}", why)
            if name == "asymmetric_damping":
                for axle, c in (("f", self.cf), ("r", self.cr)):
                    dc = (params or {}).get(f"dc_{axle}", 0.0)
                    if abs(dc) >= 2 * c and dc != 0.0:
                        raise _KeyedError(
                            f"{key}.dc_{axle}",
                            f"|dc_{axle}| = {abs(dc):g} N s/m must stay below 2 c{axle} = {2 * c:g} N s/m, "
                            "or the compression or rebound damping turns negative",
                        )
            if name == "backlash":
                for axle, c in (("f", self.cf), ("r", self.cr)):
                    if (params or {}).get(f"gap_{axle}", 0.0) > 0.0 and c <= 0.0:
                        raise _KeyedError(f"{key}.gap_{axle}", f"backlash needs a damper: c{axle} is 0")
        return self

    def effect_values(self) -> dict[str, dict[str, float]]:
        """The declared effects with every parameter resolved (defaults for those not given)."""
        return {name: {**LIBRARY[name].defaults(), **(p or {})} for name, p in (self.effects or {}).items()}

    @model_validator(mode="after")
    def _geometry(self) -> Vehicle:
        for near, far, total, what in (("a1", "a2", "wheelbase", "wheelbase"), ("b1", "b2", "track", "track")):
            d_near, d_far, d_total = getattr(self, near), getattr(self, far), getattr(self, total)
            if d_far is None and d_total is None:
                raise _KeyedError(f"vehicle.{far}", f"give either '{far}' or '{total}'")
            if d_total is not None:
                if d_near >= d_total:
                    raise _KeyedError(
                        f"vehicle.{near}",
                        f"{near} = {d_near:g} m puts the centre of gravity outside the {what} "
                        f"({total} = {d_total:g} m); expected 0 < {near} < {d_total:g}",
                    )
                if d_far is not None and abs(d_near + d_far - d_total) > 1e-9 * d_total:
                    raise _KeyedError(
                        f"vehicle.{total}",
                        f"{near} + {far} = {d_near + d_far:g} m disagrees with {total} = {d_total:g} m",
                    )
        return self

    @property
    def L(self) -> float:
        """Wheelbase a1 + a2 [m], held fixed when the CG moves."""
        return self.wheelbase if self.wheelbase is not None else self.a1 + self.a2

    @property
    def w(self) -> float:
        """Track b1 + b2 [m], held fixed when the CG moves."""
        return self.track if self.track is not None else self.b1 + self.b2

    def values(self) -> dict[str, float]:
        """All 16 model parameters, with a2 and b2 resolved from wheelbase and track."""
        out = {name: getattr(self, name) for name in VEHICLE_PARAMETERS}
        out["a2"] = self.L - self.a1
        out["b2"] = self.w - self.b1
        return out


ROAD_CHANNELS = ("road1", "road2", "road3", "road4", "track1", "track2")  # the road's names in data.channels
FAMILIES = ("acc", "disp")  # a unit for every channel of a family: data.units.acc


class Bump(_Section):
    """A discrete obstacle met at constant speed; the rear tyres meet it (a1 + a2)/V after the front."""

    shape: BumpShape = "cosine_step"
    length: within(1e-4, 100, low_open=True) = Field(
        0.1, description="ramp length (cosine_step, trapezoid) or bump length (half_sine) [m]"
    )
    plateau: within(0, 1000) = Field(0.0, description="length of the flat top of a trapezoid [m]")
    heights: tuple[Height, Height, Height, Height] = Field(description="height under corners 1..4 [m]")
    start_time: within(0, 1e6) = Field(0.1, description="time at which the front tyres meet the bump [s]")


IsoClass = Literal["A", "B", "C", "D", "E", "F", "G", "H"]


class RandomRoad(_Section):
    """A random road of an ISO 8608 class; the two wheel tracks are independent, rear follows front."""

    iso_class: IsoClass
    n_min: within(1e-4, 1000) = Field(0.01, description="lowest spatial frequency [cycles/m]")
    n_max: within(1e-4, 1000) = Field(10.0, description="highest spatial frequency [cycles/m]")
    fade_in: within(0, 1e6) = Field(5.0, description="distance over which the roughness fades in from zero [m]")

    @model_validator(mode="after")
    def _band(self) -> RandomRoad:
        if self.n_max <= self.n_min:
            raise ValueError(f"n_max = {self.n_max:g} must exceed n_min = {self.n_min:g} cycles/m")
        return self


RoadInput = Literal["actuators", "tracks", "config"]


class Road(_Section):
    """Road input: bumps and/or a random ISO 8608 road, or a road profile from a measurement file."""

    speed_kmh: within(0, 1000, low_open=True) | None = Field(None, description="forward speed [km/h]")
    speed: within(0, 300, low_open=True) | None = Field(
        None, description="forward speed [m/s], alternative to speed_kmh"
    )
    bump: Bump | None = None
    random: RandomRoad | None = None
    file: str | None = Field(None, description="measurement file whose road1..road4 columns and time grid are used")
    input: RoadInput = Field(
        "actuators",
        description="where a measured run's road comes from: actuators (channels road1..road4: a four-post rig's "
        "actuator displacements, or the road columns of a measurement CSV), tracks (channels track1, track2: one "
        "measured profile per side, under the front wheels; the rear follows wheelbase/speed later), or config "
        "(the configured bumps or random road on the run's time grid)",
    )

    @model_validator(mode="after")
    def _one_source(self) -> Road:
        if self.speed_kmh is not None and self.speed is not None:
            raise ValueError("give either 'speed_kmh' or 'speed', not both")
        if self.input == "tracks" and self.speed_kmh is None and self.speed is None:
            raise _KeyedError("road.speed_kmh", "input 'tracks' delays the rear by wheelbase/speed: give the speed")
        if self.file is None and (self.bump is not None or self.random is not None):
            if self.speed_kmh is None and self.speed is None:
                raise ValueError("give the forward speed as 'speed_kmh' (km/h) or 'speed' (m/s)")
        return self

    @property
    def configured(self) -> bool:
        """A road to simulate on: bumps, a random road or a road file."""
        return self.file is not None or self.bump is not None or self.random is not None

    @property
    def V(self) -> float:
        """Forward speed [m/s]."""
        if self.speed is not None:
            return self.speed
        if self.speed_kmh is not None:
            return self.speed_kmh / 3.6
        raise InputError("no forward speed configured", key="road.speed_kmh")


class Simulation(_Section):
    """Time grid and integrator."""

    duration: within(0, 1e5, low_open=True) = Field(3.0, description="simulated time [s]")
    dt: within(1e-7, 1) = Field(0.001, description="time step [s]")
    integrator: Literal["exact", "newmark", "exact-reference", "rk4"] = Field(
        "exact",
        description="exact: first-order-hold exact discretisation (compiled modal recursions); newmark: average "
        "acceleration; exact-reference: the same as exact in plain NumPy, slower, for cross-checks; rk4: the "
        "compiled fourth-order kernel (with vehicle.effects: rk4 or newmark, chosen explicitly)",
    )
    substeps: Annotated[int, Field(ge=1, le=1000)] | None = Field(
        None, description="rk4/newmark with effects: integration steps per sample (the kernel runs at dt/substeps)"
    )

    @model_validator(mode="after")
    def _grid(self) -> Simulation:
        if self.dt * 2 > self.duration:
            raise ValueError(f"dt = {self.dt:g} s leaves fewer than 3 samples in duration = {self.duration:g} s")
        steps = self.duration / self.dt * (self.substeps or 1)
        if steps > SIMULATION_STEPS and self.substeps:
            raise ValueError(
                f"duration/dt x substeps = {steps:.3g} integration steps is more than {SIMULATION_STEPS:,}: fewer "
                "substeps, a larger dt or a shorter duration"
            )
        if self.duration / self.dt > SIMULATION_SAMPLES:
            raise ValueError(
                f"duration/dt = {self.duration / self.dt:.3g} samples is more than {SIMULATION_SAMPLES:,} "
                "(a longer record than any test needs: a larger dt or a shorter duration)"
            )
        return self


class NoiseSigma(_Section):
    """Absolute noise floors per sensor family: a real sensor's noise does not grow with the signal."""

    acc: within(0, 1e4, low_open=True) | None = Field(
        None, description="standard deviation of every acceleration channel [m/s²]"
    )
    disp: within(0, 10, low_open=True) | None = Field(
        None, description="standard deviation of every displacement/deflection channel [m]"
    )


class Noise(_Section):
    """Measurement noise: Gökdağ Eq. 15 (sigma_i = level * std(clean channel i)) by default; `sigma` gives a family
    an absolute floor instead (a sensor's own `sigma` in the layout wins over both)."""

    level: Annotated[float, Field(ge=0, le=10, allow_inf_nan=False)] = Field(0.0, description="Np, 0.1 = 10 %")
    sigma: NoiseSigma = NoiseSigma()

    def describe(self) -> str:
        """The noise in a few words (file comments, figures, summaries)."""
        units = {"acc": "m/s²", "disp": "m"}
        parts = [f"sigma_{f} = {v:g} {units[f]}" for f, v in self.sigma.model_dump().items() if v is not None]
        if self.level > 0 or not parts:
            parts.insert(0, f"Np = {100 * self.level:g} % (Eq. 15)")
        return ", ".join(parts)


Offsets = Literal["none", "remove", "identify"]


class VehicleData(_Section):
    """Measured runs as a data logger records them: which channel of the file is which sensor, in which unit."""

    files: tuple[str, ...] = Field(
        (), description="runs identified jointly (relative to the config); --data replaces them"
    )
    channels: dict[str, str] = Field(
        {},
        description="our name (a sensor of the layout, road1..road4, track1, track2) -> the channel's name in the "
        "file; a name left out is looked up as itself",
    )
    units: dict[str, str] = Field(
        {},
        description="our name (or a family, acc or disp, for all its channels) -> the unit of its channel in the file "
        "(g, mm, ...); a channel without one takes its family's, else the unit its file declares (MDF4, HDF5, a CSV "
        "header 'NAME [g]'), else SI",
    )
    invert: tuple[str, ...] = Field((), description="channels whose sign the chain inverts (a sensor upside down)")
    swap: tuple[tuple[str, str], ...] = Field((), description="pairs of channels whose connectors are swapped")
    time: str | None = Field(None, description="the time column/vector (CSV, MAT, HDF5; default t or time)")
    time_unit: str = Field("s", description="unit of a numeric time column")
    window: tuple[NonNeg, Pos] | None = Field(None, description="use only start <= t < stop [s] of each run")
    rate: Pos | None = Field(
        None,
        description="rate of the common grid [Hz] (default: the fastest channel's; slower channels are "
        "compared at their own samples only)",
    )
    resample: bool = Field(True, description="false: channels at different rates (or jittered stamps) are an error")
    variable: str | None = Field(None, description="the MAT struct (or HDF5 group) holding the channels")
    offsets: Offsets = Field(
        "none",
        description="sensor offsets (bias, gravity, a potentiometer's zero): none; remove (each channel's mean over "
        "the first second, the car at rest); identify (one nuisance offset per channel and run, profiled out of the "
        "fit and the bound)",
    )

    @model_validator(mode="after")
    def _checks(self) -> VehicleData:
        for ours, unit in self.units.items():
            if unit not in SI_FACTORS:
                raise _KeyedError(
                    f"data.units.{ours}",
                    f"unknown unit '{unit}'{_did_you_mean(unit, SI_FACTORS)} (known: {', '.join(SI_FACTORS)})",
                )
        if self.time_unit not in UNITS["time"]:
            raise _KeyedError(
                "data.time_unit", f"unknown time unit '{self.time_unit}' (known: {', '.join(UNITS['time'])})"
            )
        if self.window is not None and not self.window[0] < self.window[1]:
            raise _KeyedError("data.window", f"start {self.window[0]:g} s must be before stop {self.window[1]:g} s")
        return self


class Identify(IdentifyCommon):
    """What to identify and how (common.IdentifyCommon), with the car's objective. Bounds are relative to the
    configured (true or nominal) values."""

    unknowns: Annotated[tuple[str, ...], Field(min_length=1)] = ("m", "Ix", "Iy", "a1", "b1")
    objective: Literal["f1", "f2", "wls"] = "f2"


class Config(SystemConfig):
    """A whole experiment: the car, the road, the time grid, the sensors, the noise, the identification."""

    system: Literal["vehicle"] = "vehicle"
    vehicle: Vehicle
    road: Road
    simulation: Simulation = Simulation()
    sensors: Literal["acc", "disp", "both"] = Field(
        "both", description="the families wls compares: acc, disp or both (of the layout's channels)"
    )
    layout: tuple[SensorSpec, ...] | None = Field(
        None, description="the sensors (default: the paper's acc1..acc4, disp1..disp4 above the corners)"
    )
    noise: Noise = Noise()
    data: VehicleData = VehicleData()
    identify: Identify = Identify()
    design: Design | None = Field(None, description="limits of the test `vehid design` plans (config/design.py)")

    def channel_unit(self, channel: str) -> str:
        """The SI unit of a sensor of the layout (models.sensors.UNIT of its family); '' for another name."""
        kind = next((s.kind for s in self.sensor_layout().sensors if s.name == channel), None)
        return "" if kind is None else UNIT[FAMILY[kind]]

    def sensor_layout(self) -> Layout:
        """The configured sensors (models.sensors.Layout), the paper's corner layout when none is given."""
        return corner_layout() if self.layout is None else Layout(tuple(s.sensor() for s in self.layout))

    @model_validator(mode="after")
    def _road(self) -> Config:
        measured = bool(self.data.files or self.data.channels)
        if not self.road.configured and not measured:
            raise _KeyedError("road", "give a 'bump', a 'random' road, or a road 'file'")
        if self.road.input == "config" and not self.road.configured:
            raise _KeyedError(
                "road.input", "input 'config' takes the configured road: give a 'bump' or a 'random' road"
            )
        return self

    @model_validator(mode="after")
    def _layout(self) -> Config:
        if self.layout is None:
            return self
        names = [s.name for s in self.layout]
        for i, name in enumerate(names):
            if name in names[:i]:
                raise _KeyedError(f"layout.{i}.name", f"sensor name '{name}' is used twice")
            if name in ROAD_CHANNELS:
                raise _KeyedError(f"layout.{i}.name", f"'{name}' names a road channel; choose another sensor name")
        if not self.layout:
            raise _KeyedError("layout", "an empty layout measures nothing: list at least one sensor, or remove it")
        families = {FAMILY[s.kind] for s in self.layout}
        wanted = {"acc": {"acc"}, "disp": {"disp"}, "both": {"acc", "disp"}}[self.sensors]
        if not families & wanted:
            raise _KeyedError(
                "sensors", f"sensors '{self.sensors}' selects no channel of the layout ({', '.join(sorted(families))})"
            )
        return self

    @model_validator(mode="after")
    def _data_names(self) -> Config:
        """Every name in data.channels, data.units, data.invert and data.swap is a channel of the layout (or a road
        input; a family for a unit): a typo would otherwise be ignored silently."""
        layout = self.sensor_layout()
        channels = tuple(s.name for s in layout.sensors)
        known = channels + ROAD_CHANNELS
        data = self.data
        entries = [("channels", n, known) for n in data.channels] + [("units", n, known + FAMILIES) for n in data.units]
        entries += [("invert", n, channels) for n in data.invert]
        entries += [("swap", n, channels) for pair in data.swap for n in pair]
        for key, name, allowed in entries:
            if name not in allowed:
                hint = _did_you_mean(name, allowed)
                listing = "" if hint else f" (the layout's channels: {', '.join(channels)})"
                raise _KeyedError(f"data.{key}.{name}" if key in ("channels", "units") else f"data.{key}",
                                  f"'{name}' is not a channel of the layout{hint}{listing}")  # fmt: skip
        return self

    @model_validator(mode="after")
    def _effects_need_time_stepping(self) -> Config:
        sim = self.simulation
        if self.vehicle.effects and sim.integrator not in ("rk4", "newmark"):
            raise _KeyedError(
                "simulation.integrator",
                f"vehicle.effects ({', '.join(self.vehicle.effects)}) make the car nonlinear: the '{sim.integrator}' "
                "integrator is for the linear car; set simulation.integrator to rk4 (order 4) or newmark (order 2)",
            )
        if sim.substeps not in (None, 1) and sim.integrator not in ("rk4", "newmark"):
            raise _KeyedError(
                "simulation.substeps", f"substeps are for the rk4 and newmark kernels, not '{sim.integrator}'"
            )
        return self

    def parameter_values(self) -> dict[str, float]:
        """Every identifiable value: the car's parameters and the declared effects' (<effect>.<param>)."""
        effects = {f"{e}.{k}": float(v) for e, ps in self.vehicle.effect_values().items() for k, v in ps.items()}
        return {**self.vehicle.values(), **effects}

    @model_validator(mode="after")
    def _identify_against_vehicle(self) -> Config:
        ident, values = self.identify, self.parameter_values()
        for name in ident.unknowns:
            if name not in values:
                hint = _did_you_mean(name, tuple(values))
                what = "a vehicle parameter or a parameter of a declared effect (vehicle.effects)"
                raise _KeyedError("identify.unknowns", f"'{name}' is not {what}{hint}")
            if "." in name and values[name] == 0 and name not in ident.limits:
                raise _KeyedError(
                    f"identify.limits.{name}",
                    f"'{name}' is 0 in the config, so 'bounds' (factors) give no range: set identify.limits.{name}",
                )
        ident.check_names()
        for pair in (("a1", "a2"), ("b1", "b2")):
            if set(pair) <= set(ident.unknowns):
                raise _KeyedError(
                    "identify.unknowns", f"'{pair[0]}' and '{pair[1]}' cannot both be unknown: their sum is fixed"
                )
        families = self.sensor_layout().families
        if ident.objective == "f1" and "disp" not in families:
            raise _KeyedError("identify.objective", "f1 compares displacements; the layout has no displacement sensor")
        if ident.objective == "f2" and "acc" not in families:
            raise _KeyedError("identify.objective", "f2 compares accelerations; the layout has no accelerometer")
        if ident.objective == "f1" and self.sensors == "acc":
            raise _KeyedError("identify.objective", "f1 compares displacements; set sensors to 'disp' or 'both'")
        if ident.objective == "f2" and self.sensors == "disp":
            raise _KeyedError("identify.objective", "f2 compares accelerations; set sensors to 'acc' or 'both'")
        box = self.search_box()
        ident.check_box(values, box, _parameter_range)
        for name, (lo, hi) in box.items():
            span = {"a1": self.vehicle.L, "a2": self.vehicle.L, "b1": self.vehicle.w, "b2": self.vehicle.w}.get(name)
            if span is not None and (lo <= 0 or hi >= span):
                raise _KeyedError(
                    f"identify.limits.{name}" if name in ident.limits else "identify.bounds",
                    f"the search range [{lo:g}, {hi:g}] m of '{name}' leaves the "
                    f"{'wheelbase' if name[0] == 'a' else 'track'} ({span:g} m); keep it inside (0, {span:g})",
                )
            if lo <= 0 and "." not in name and name not in ("kR", "cf", "cr"):
                raise _KeyedError(f"identify.limits.{name}", f"'{name}' must stay positive; got lower limit {lo:g}")
        return self

    def search_box(self) -> dict[str, tuple[float, float]]:
        """Search range of each unknown [SI units]: 'limits' where given, else 'bounds' x configured value."""
        return self.identify.box(self.parameter_values())

    def edits_for(self, values: Mapping[str, float]) -> list[ConfigEdit]:
        """`vehicle.<name>` for the car's parameters, `vehicle.effects.<effect>.<param>` for an effect's (an effect
        the config lacks makes the integrator rk4, as `diagnose` fitted it); a1 (b1) keeps the wheelbase (track):
        a2 (b2), where the config gives it, becomes the rest (SPEC section 1)."""
        v, out = self.vehicle, []
        spans = {"a1": ("a2", v.L, "wheelbase"), "a2": ("a1", v.L, "wheelbase"),
                 "b1": ("b2", v.w, "track"), "b2": ("b1", v.w, "track")}  # fmt: skip
        for name, value in values.items():
            if "." in name:
                out.append(ConfigEdit(f"vehicle.effects.{name}", float(value), name))
                continue
            out.append(ConfigEdit(f"vehicle.{name}", float(value), name))
            if name in spans and getattr(v, spans[name][0]) is not None:
                other, span, what = spans[name]
                note = f"{what} {span:g} m kept: {span:g} - {name}"
                out.append(ConfigEdit(f"vehicle.{other}", span - float(value), None, note))
        new = {n.partition(".")[0] for n in values if "." in n} - set(v.effects or {})
        if new and self.simulation.integrator not in ("rk4", "newmark"):
            note = f"{', '.join(sorted(new))} make the car nonlinear: rk4, as vehid diagnose fitted it"
            out.append(ConfigEdit("simulation.integrator", "rk4", None, note))
        return out

    def resolved(self, path: Path) -> Config:
        """The road file and the data runs named relative to the config file, resolved against its directory."""
        cfg = self
        if cfg.road.file is not None and not Path(cfg.road.file).is_absolute():
            road = cfg.road.model_copy(update={"file": (path.parent / cfg.road.file).as_posix()})
            cfg = cfg._relocated({"road": road})
        if cfg.data.files:
            files = tuple(f if Path(f).is_absolute() else (path.parent / f).as_posix() for f in cfg.data.files)
            cfg = cfg._relocated({"data": cfg.data.model_copy(update={"files": files})})
        return cfg

    def data_runs(self) -> tuple[str, ...]:
        """The runs of data.files (identified jointly when there are several)."""
        return tuple(self.data.files)
