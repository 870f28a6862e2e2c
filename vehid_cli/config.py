"""Experiment configuration: YAML -> validated, frozen pydantic models, with `--set` overrides.

Every problem a user can make in a config is reported as an :class:`InputError` that names the file
and the dotted key, with a did-you-mean for unknown keys (exit status 2 on the command line).
"""

from __future__ import annotations

import difflib
import hashlib
import json
import types
import typing
from pathlib import Path
from typing import Annotated, Any, Literal, Union

import yaml
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, PrivateAttr, ValidationError, model_validator

from .bench import UNITS
from .errors import InputError
from .models.damper import MODELS, default_values
from .models.effects import BENCH_EFFECTS, LIBRARY, bound_violation
from .models.fullcar import VEHICLE_PARAMETERS
from .optimizers import REGISTRY, load_all

Pos = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNeg = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]


class _Section(BaseModel):
    """Base of every config section: unknown keys are errors, values are immutable, ints become floats."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=False)


class Vehicle(_Section):
    """The 7-DOF full car (Gökdağ Fig. 1). SI units: kg, kg m², m, N/m, N m/rad (kR), N s/m."""

    m: Pos = Field(description="sprung (body) mass [kg]")
    mf: Pos = Field(description="front unsprung mass, each [kg]")
    mr: Pos = Field(description="rear unsprung mass, each [kg]")
    Ix: Pos = Field(description="roll moment of inertia [kg m²]")
    Iy: Pos = Field(description="pitch moment of inertia [kg m²]")
    a1: Pos = Field(description="CG to front axle [m]")
    a2: Pos | None = Field(None, description="CG to rear axle [m]; or give wheelbase")
    b1: Pos = Field(description="CG to side-1 wheels (corners 1, 4) [m]")
    b2: Pos | None = Field(None, description="CG to side-2 wheels (corners 2, 3) [m]; or give track")
    wheelbase: Pos | None = Field(None, description="a1 + a2 [m], alternative to a2")
    track: Pos | None = Field(None, description="b1 + b2 [m], alternative to b2")
    kf: Pos = Field(description="front suspension stiffness [N/m]")
    kr: Pos = Field(description="rear suspension stiffness [N/m]")
    ktf: Pos = Field(description="front tyre stiffness [N/m]")
    ktr: Pos = Field(description="rear tyre stiffness [N/m]")
    kR: NonNeg = Field(0.0, description="front anti-roll bar stiffness [N m/rad]")
    cf: NonNeg = Field(description="front suspension damping [N s/m]")
    cr: NonNeg = Field(description="rear suspension damping [N s/m]")
    effects: dict[str, dict[str, Finite] | None] | None = Field(
        None,
        description="nonlinear effects beside the linear car: effect name -> its parameters "
        "(vehid_cli/models/effects.py; missing parameters at their defaults); "
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


BumpShape = Literal["step", "cosine_step", "half_sine", "trapezoid"]


class Bump(_Section):
    """A discrete obstacle met at constant speed; the rear tyres meet it (a1 + a2)/V after the front."""

    shape: BumpShape = "cosine_step"
    length: Pos = Field(0.1, description="ramp length (cosine_step, trapezoid) or bump length (half_sine) [m]")
    plateau: NonNeg = Field(0.0, description="length of the flat top of a trapezoid [m]")
    heights: tuple[Finite, Finite, Finite, Finite] = Field(description="height under corners 1..4 [m]")
    start_time: NonNeg = Field(0.1, description="time at which the front tyres meet the bump [s]")


IsoClass = Literal["A", "B", "C", "D", "E", "F", "G", "H"]


class RandomRoad(_Section):
    """A random road of an ISO 8608 class; the two wheel tracks are independent, rear follows front."""

    iso_class: IsoClass
    n_min: Pos = Field(0.01, description="lowest spatial frequency [cycles/m]")
    n_max: Pos = Field(10.0, description="highest spatial frequency [cycles/m]")
    fade_in: NonNeg = Field(5.0, description="distance over which the roughness fades in from zero [m]")

    @model_validator(mode="after")
    def _band(self) -> RandomRoad:
        if self.n_max <= self.n_min:
            raise ValueError(f"n_max = {self.n_max:g} must exceed n_min = {self.n_min:g} cycles/m")
        return self


class Road(_Section):
    """Road input: bumps and/or a random ISO 8608 road, or a road profile from a measurement file."""

    speed_kmh: Pos | None = Field(None, description="forward speed [km/h]")
    speed: Pos | None = Field(None, description="forward speed [m/s], alternative to speed_kmh")
    bump: Bump | None = None
    random: RandomRoad | None = None
    file: str | None = Field(None, description="measurement file whose road1..road4 columns and time grid are used")

    @model_validator(mode="after")
    def _one_source(self) -> Road:
        if self.speed_kmh is not None and self.speed is not None:
            raise ValueError("give either 'speed_kmh' or 'speed', not both")
        if self.file is None:
            if self.bump is None and self.random is None:
                raise ValueError("give a 'bump', a 'random' road, or a road 'file'")
            if self.speed_kmh is None and self.speed is None:
                raise ValueError("give the forward speed as 'speed_kmh' (km/h) or 'speed' (m/s)")
        return self

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

    duration: Pos = Field(3.0, description="simulated time [s]")
    dt: Pos = Field(0.001, description="time step [s]")
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
        if self.duration / self.dt > 10_000_000:
            raise ValueError(f"duration/dt = {self.duration / self.dt:.3g} samples is more than 10 million")
        return self


class Noise(_Section):
    """Measurement noise of Gökdağ Eq. 15: sigma_i = level * std(clean channel i)."""

    level: Annotated[float, Field(ge=0, le=10, allow_inf_nan=False)] = Field(0.0, description="Np, 0.1 = 10 %")


class Algorithm(_Section):
    """Identification algorithm and its budget."""

    name: str = Field("abc", description="an optimizer of vehid_cli/optimizers (SPEC section 3 names)")
    population: Annotated[int, Field(ge=2)] = 20
    iterations: Annotated[int, Field(ge=1)] = 50


def _start_alias(value: object) -> object:
    """`nominal` is the old name of `config` (vehicle configs before the vocabulary was shared)."""
    return "config" if value == "nominal" else value


Start = Annotated[Literal["auto", "random", "config"], BeforeValidator(_start_alias)]  # one vocabulary for all systems


class Identify(_Section):
    """What to identify and how. Bounds are relative to the configured (true or nominal) values."""

    unknowns: Annotated[tuple[str, ...], Field(min_length=1)] = ("m", "Ix", "Iy", "a1", "b1")
    bounds: tuple[Pos, Pos] = Field((0.7, 1.3), description="search range as factors of the configured values")
    limits: dict[str, tuple[Finite, Finite]] = Field(
        default_factory=dict, description="absolute search range per unknown, overriding 'bounds'"
    )
    objective: Literal["f1", "f2", "wls"] = "f2"
    algorithm: Algorithm = Algorithm()
    runs: Annotated[int, Field(ge=1)] = 30
    seed: Annotated[int, Field(ge=0)] = 2015
    budget: Annotated[int, Field(ge=1)] | None = Field(
        None, description="model evaluations per run; default population x iterations"
    )
    start: Start = Field(
        "random",
        description="where a run starts: random (the optimizer's own random start from the run's stream), config "
        "(the configured values), auto (random for simulated data, config for measured data)",
    )
    truth: Literal["auto", "config", "none"] = Field(
        "auto",
        description="are the configured values the truth? auto: yes for simulated data, no with --data",
    )


class Config(_Section):
    """A whole experiment: the car, the road, the time grid, the sensors, the noise, the identification."""

    system: Literal["vehicle"] = "vehicle"
    vehicle: Vehicle
    road: Road
    simulation: Simulation = Simulation()
    sensors: Literal["acc", "disp", "both"] = "both"
    noise: Noise = Noise()
    identify: Identify = Identify()

    _source: str = PrivateAttr(default="<config>")

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
        seen = set()
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
            if name in seen:
                raise _KeyedError("identify.unknowns", f"'{name}' is listed twice")
            seen.add(name)
        for pair in (("a1", "a2"), ("b1", "b2")):
            if set(pair) <= seen:
                raise _KeyedError(
                    "identify.unknowns", f"'{pair[0]}' and '{pair[1]}' cannot both be unknown: their sum is fixed"
                )
        _check_algorithm(ident.algorithm)
        for name in ident.limits:
            if name not in ident.unknowns:
                raise _KeyedError(
                    f"identify.limits.{name}", f"'{name}' is not one of the unknowns {list(ident.unknowns)}"
                )
        if ident.objective == "f1" and self.sensors == "acc":
            raise _KeyedError("identify.objective", "f1 compares displacements; set sensors to 'disp' or 'both'")
        if ident.objective == "f2" and self.sensors == "disp":
            raise _KeyedError("identify.objective", "f2 compares accelerations; set sensors to 'acc' or 'both'")
        lo_f, hi_f = ident.bounds
        if not lo_f < hi_f:
            raise _KeyedError("identify.bounds", f"lower factor {lo_f:g} must be below upper factor {hi_f:g}")
        for name, (lo, hi) in self.search_box().items():
            if not lo < hi:
                raise _KeyedError(f"identify.limits.{name}", f"lower limit {lo:g} must be below upper limit {hi:g}")
            if not lo <= values[name] <= hi:
                raise _KeyedError(
                    f"identify.limits.{name}" if name in ident.limits else "identify.bounds",
                    f"the search range [{lo:g}, {hi:g}] of '{name}' excludes its configured value {values[name]:g}",
                )
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
        values, ident = self.parameter_values(), self.identify
        lo_f, hi_f = ident.bounds
        box = {n: ident.limits.get(n, (lo_f * values[n], hi_f * values[n])) for n in ident.unknowns}
        return {n: (min(lo, hi), max(lo, hi)) for n, (lo, hi) in box.items()}

    @property
    def source(self) -> str:
        """The file the config was read from (for messages and relative paths)."""
        return self._source

    def to_yaml(self) -> str:
        """The resolved config as YAML text (defaults filled in, overrides applied)."""
        return yaml.safe_dump(self.model_dump(mode="json", exclude_none=True), sort_keys=False)

    def digest(self) -> str:
        """SHA-256 of the resolved config, independent of key order and formatting."""
        canonical = json.dumps(self.model_dump(mode="json", exclude_none=True), sort_keys=True)
        return hashlib.sha256(canonical.encode()).hexdigest()


# ------------------------------------------------------------------------------------------ dampers

DAMPER_STRUCTURAL = ("m", "nv", "nu")  # table sizes: set by damper.table, never identified


class DamperSection(_Section):
    """The damper model (Fleps-Dezasse section 3) and its parameter values [SI: N, m, s; u in 0..1]."""

    model: str = Field(description="viscous, bingham, gas_spring, bouc_wen, generalized_bouc_wen or force_map")
    table: tuple[Annotated[int, Field(ge=1, le=50)], ...] = Field(
        (), description="table shape: [m] nodes over u (generalized_bouc_wen), [nv, nu] (force_map)"
    )
    parameters: dict[str, Finite] = Field(
        default_factory=dict,
        description="values by name: the truth for synthetic data, the start for fits; the rest from defaults",
    )
    effects: dict[str, dict[str, Finite]] = Field(
        default_factory=dict,
        description="library effects around the damper on the bench, e.g. {hysteresis: {alpha: 2e5}} (a truth "
        "config for data with an effect the identification config does not declare); their parameters are "
        "named <effect>.<param> in identify.unknowns",
    )


class BenchSection(_Section):
    """The virtual test bench (Fleps-Dezasse section 4.2) that synthetic data is simulated on."""

    excitation: Literal["sine", "sawtooth", "constant_velocity"] = "sine"
    amplitude: Pos = Field(0.025, description="displacement amplitude [m] (stroke/2 for constant_velocity)")
    frequency: Pos = Field(0.8, description="sine frequency [Hz]")
    velocity: Pos = Field(0.15, description="|velocity| of sawtooth and constant_velocity [m/s]")
    cycles: Pos = Field(3.0, description="number of periods (sine, sawtooth)")
    dt: Pos = Field(0.001, description="sampling step of the bench history [s]")
    control: Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)] = Field(
        0.0, description="control input u [0..1] (sine, constant_velocity; the base level of the sawtooth)"
    )
    steps: tuple[tuple[NonNeg, Annotated[float, Field(ge=0, le=1)]], ...] | None = Field(
        None, description="control steps [(time [s], u), ...] of the sawtooth; default the paper's 15-50-15 %"
    )
    substeps: Annotated[int, Field(ge=1, le=1000)] = Field(
        1, description="integration steps per sample: the integrator runs at dt / substeps"
    )

    @model_validator(mode="after")
    def _grid(self) -> BenchSection:
        samples = self.cycles / self.frequency / self.dt if self.excitation == "sine" else 0
        if samples > 2_000_000:
            raise ValueError(f"the sine holds {samples:.3g} samples; keep it below 2 million")
        return self


class DataColumns(_Section):
    """Column names of a bench file; velocity is differentiated from displacement and control is 0 when absent."""

    time: str = "t"
    displacement: str = "x"
    force: str = "force"
    velocity: str | None = None
    control: str | None = None


class DataUnits(_Section):
    """Units of the columns (see vehid_cli.bench.UNITS)."""

    time: str = "s"
    displacement: str = "m"
    force: str = "N"
    velocity: str = "m/s"
    control: str = "1"


class DamperData(_Section):
    """Measured bench runs: the training file, its columns and units, and held-out validation files."""

    file: str | None = Field(None, description="training run (CSV); relative paths are relative to the config")
    columns: DataColumns = DataColumns()
    units: DataUnits = DataUnits()
    window: tuple[NonNeg, Pos] | None = Field(None, description="use only start <= t < stop [s] of each file")
    decimate: Annotated[int, Field(ge=1, le=1000)] = Field(1, description="keep every n-th sample (for speed)")
    sample_rate: Pos | None = Field(
        None,
        description="nominal sampling rate [Hz] of files whose time column was printed with too few digits to be "
        "uniform: time is rebuilt as t0 + k / rate after checking it increases and agrees within 5 %",
    )
    validate_files: tuple[str, ...] = Field((), alias="validate", description="held-out runs, same columns")

    model_config = ConfigDict(extra="forbid", frozen=True, strict=False, populate_by_name=True)

    @model_validator(mode="after")
    def _window(self) -> DamperData:
        for role, table in UNITS.items():
            unit = getattr(self.units, role)
            if unit not in table:
                column = getattr(self.columns, role)
                of = f" of column '{column}'" if column else ""
                raise _KeyedError(
                    f"data.units.{role}",
                    f"unknown {role} unit '{unit}'{of}{_did_you_mean(unit, table)} (known: {', '.join(table)})",
                )
        if self.window is not None and not self.window[0] < self.window[1]:
            raise _KeyedError("data.window", f"start {self.window[0]:g} s must be before stop {self.window[1]:g} s")
        return self


class DamperNoise(_Section):
    """Force noise of synthetic bench data: sigma = level * std(clean force)."""

    level: Annotated[float, Field(ge=0, le=10, allow_inf_nan=False)] = Field(0.0, description="0.02 = 2 %")


class DamperStage(_Section):
    """One stage of the step-by-step identification (Fleps-Dezasse section 4.2): its unknowns, fitted on its
    own experiment: a bench excitation (synthetic data) or a measured file."""

    name: str
    unknowns: Annotated[tuple[str, ...], Field(min_length=1)]
    bench: BenchSection | None = Field(None, description="the excitation of this stage (synthetic data)")
    file: str | None = Field(None, description="the measured run of this stage (relative to the config)")


class DamperIdentify(_Section):
    """What to identify and how (cost J, Fleps-Dezasse Eq. 7). Bounds are factors of the configured values."""

    unknowns: Annotated[tuple[str, ...], Field(min_length=1)]
    bounds: tuple[Pos, Pos] = Field((0.1, 10.0), description="search range as factors of the configured values")
    limits: dict[str, tuple[Finite, Finite]] = Field(
        default_factory=dict, description="absolute search range per unknown [SI], overriding 'bounds'"
    )
    algorithm: Algorithm = Algorithm(name="nelder-mead", population=20, iterations=100)
    budget: Annotated[int, Field(ge=1)] | None = Field(
        None, description="model evaluations per fit; default population x iterations"
    )
    runs: Annotated[int, Field(ge=1)] = 10
    seed: Annotated[int, Field(ge=0)] = 2013
    start: Start = Field(
        "auto",
        description="where a fit starts: a random point in the box (from the run's stream) or the configured "
        "values; auto: random for synthetic data, config for measured data",
    )
    truth: Literal["auto", "config", "none"] = Field(
        "auto", description="are the configured values the truth? auto: yes for synthetic data, no for files"
    )
    realtime_dt: Pos = Field(0.001, description="step of the real-time check (fixed-step RK4) [s]")
    stages: tuple[DamperStage, ...] = Field(
        (),
        description="step-by-step identification: stages in order, each starting from what the previous found "
        "(e.g. gas force on a slow stroke, then the model per control input on sines, then lag and delays on "
        "the sawtooth); their unknowns together are identify.unknowns",
    )


class DamperConfig(_Section):
    """A damper on a test bench: the model, the bench (or measured files), the noise, the identification."""

    system: Literal["damper"]
    damper: DamperSection
    bench: BenchSection = BenchSection()
    data: DamperData | None = None
    noise: DamperNoise = DamperNoise()
    identify: DamperIdentify

    _source: str = PrivateAttr(default="<config>")

    @model_validator(mode="after")
    def _consistent(self) -> DamperConfig:
        d, ident = self.damper, self.identify
        if d.model not in MODELS:
            hint = _did_you_mean(d.model, MODELS)
            raise _KeyedError("damper.model", f"unknown damper model '{d.model}'{hint} (known: {', '.join(MODELS)})")
        want = {"generalized_bouc_wen": 1, "force_map": 2}.get(d.model, 0)
        if d.model == "generalized_bouc_wen" and not d.table:
            pass  # one node: u-independent parameters
        elif len(d.table) != want:
            shape = {0: "no table (leave it out)", 1: "[m] nodes over u", 2: "[nv, nu]"}[want]
            raise _KeyedError("damper.table", f"{d.model} takes {shape}, got {list(d.table)}")
        if d.model == "force_map" and min(d.table) < 2:
            raise _KeyedError("damper.table", f"a force map needs at least 2 x 2 nodes, got {list(d.table)}")
        self._check_effects()
        names = self.parameter_names()
        for name in d.parameters:
            if name not in names:
                raise _KeyedError(
                    f"damper.parameters.{name}", f"'{name}' is not a parameter of {d.model}{_did_you_mean(name, names)}"
                )
        for name in DAMPER_STRUCTURAL:
            if name in d.parameters and d.parameters[name] != self.values()[name]:
                raise _KeyedError(f"damper.parameters.{name}", f"'{name}' is the table size: set it in damper.table")
        seen = set()
        for name in ident.unknowns:
            if name not in names:
                hint = _did_you_mean(name, names)
                raise _KeyedError("identify.unknowns", f"'{name}' is not a parameter of {d.model}{hint}")
            if name in DAMPER_STRUCTURAL:
                raise _KeyedError("identify.unknowns", f"'{name}' is a table size, not an identifiable parameter")
            if name in seen:
                raise _KeyedError("identify.unknowns", f"'{name}' is listed twice")
            seen.add(name)
        _check_algorithm(ident.algorithm)
        staged: list[str] = []
        for k, stage in enumerate(ident.stages):
            for name in stage.unknowns:
                if name not in seen:
                    raise _KeyedError(
                        f"identify.stages.{k}.unknowns",
                        f"'{name}' is not one of identify.unknowns {list(ident.unknowns)}",
                    )
                staged.append(name)
            if stage.bench is not None and stage.file is not None:
                raise _KeyedError(f"identify.stages.{k}", "give a stage either a bench excitation or a file, not both")
        if ident.stages and set(staged) != seen:
            missing = sorted(seen - set(staged))
            raise _KeyedError("identify.stages", f"no stage identifies {missing}: every unknown needs a stage")
        for name in ident.limits:
            if name not in ident.unknowns:
                raise _KeyedError(
                    f"identify.limits.{name}", f"'{name}' is not one of the unknowns {list(ident.unknowns)}"
                )
        lo_f, hi_f = ident.bounds
        if not lo_f < hi_f:
            raise _KeyedError("identify.bounds", f"lower factor {lo_f:g} must be below upper factor {hi_f:g}")
        values = self.values()
        for name, (lo, hi) in self.search_box().items():
            key = f"identify.limits.{name}" if name in ident.limits else "identify.bounds"
            if not lo < hi:
                raise _KeyedError(key, f"lower limit {lo:g} must be below upper limit {hi:g}")
            if not lo <= values[name] <= hi:
                raise _KeyedError(
                    key, f"the search range [{lo:g}, {hi:g}] of '{name}' excludes its configured value {values[name]:g}"
                )
        return self

    def _check_effects(self) -> None:
        """Bench effects exist, their parameters exist and lie in their physical bounds."""
        for name, params in self.damper.effects.items():
            if name not in BENCH_EFFECTS:
                raise _KeyedError(
                    f"damper.effects.{name}",
                    f"'{name}' is not an effect on the bench{_did_you_mean(name, BENCH_EFFECTS)} "
                    f"(known: {', '.join(BENCH_EFFECTS)}; gas force and backlash are the model's k1, x0 and gap)",
                )
            known = tuple(p.name for p in LIBRARY[name].params)
            for key, value in params.items():
                if key not in known:
                    raise _KeyedError(
                        f"damper.effects.{name}.{key}",
                        f"'{key}' is not a parameter of {name}{_did_you_mean(key, known)} (known: {', '.join(known)})",
                    )
                per_axle = next(p.per_axle for p in LIBRARY[name].params if p.name == key)
                why = bound_violation(name, f"{key}_f" if per_axle else key, value)
                if why:  # one damper: the per-axle name reads as the plain one
                    raise _KeyedError(f"damper.effects.{name}.{key}", why.replace(f"{name}.{key}_f", f"{name}.{key}"))

    def effect_parameters(self) -> tuple[str, ...]:
        """The declared bench effects' parameters, as identify.unknowns names them (<effect>.<param>)."""
        return tuple(f"{e}.{p.name}" for e in self.damper.effects for p in LIBRARY[e].params)

    def parameter_names(self) -> tuple[str, ...]:
        """Every parameter of the configured model, in the kernel's row order, then the effects' parameters."""
        return MODELS[self.damper.model].layout(self.table_shape) + self.effect_parameters()

    @property
    def table_shape(self) -> tuple[int, ...]:
        return tuple(self.damper.table)

    def values(self) -> dict[str, float]:
        """All parameter values: the configured ones over the neutral defaults (damper_fit.default_values)."""
        effects = {
            f"{e}.{p.name}": float(given.get(p.name, p.default))
            for e, given in self.damper.effects.items()
            for p in LIBRARY[e].params
        }
        return {**default_values(self.damper.model, self.table_shape), **self.damper.parameters, **effects}

    def search_box(self) -> dict[str, tuple[float, float]]:
        """Search range of each unknown [SI]: 'limits' where given, else 'bounds' x configured value
        (a symmetric range of +-1 for values at 0, where a factor means nothing)."""
        ident = self.identify
        scaled = scaled_bounds(self.values(), ident.unknowns, *ident.bounds)
        return {n: tuple(ident.limits.get(n, scaled[n])) for n in ident.unknowns}

    @property
    def source(self) -> str:
        """The file the config was read from (for messages and relative paths)."""
        return self._source

    def to_yaml(self) -> str:
        """The resolved config as YAML text (defaults filled in, overrides applied)."""
        return yaml.safe_dump(self.model_dump(mode="json", exclude_none=True, by_alias=True), sort_keys=False)

    def digest(self) -> str:
        """SHA-256 of the resolved config, independent of key order and formatting."""
        canonical = json.dumps(self.model_dump(mode="json", exclude_none=True, by_alias=True), sort_keys=True)
        return hashlib.sha256(canonical.encode()).hexdigest()


AnyConfig = Union[Config, DamperConfig]  # noqa: UP007


def _check_algorithm(algorithm: Algorithm) -> None:
    """The algorithm exists (the optimizer registry is the one list of names) and its population suffices."""
    load_all()
    cls = REGISTRY.get(algorithm.name)
    if cls is None:
        hint = _did_you_mean(algorithm.name, REGISTRY)
        known = "" if hint else f" (known: {', '.join(sorted(REGISTRY))})"
        raise _KeyedError("identify.algorithm.name", f"unknown algorithm '{algorithm.name}'{hint}{known}")
    if algorithm.population < cls.min_population:
        raise _KeyedError(
            "identify.algorithm.population",
            f"{algorithm.name} needs a population of at least {cls.min_population}, got {algorithm.population}",
        )


class _KeyedError(ValueError):
    """A validation error attached to a dotted key other than the one pydantic is validating."""

    def __init__(self, key: str, message: str):
        super().__init__(message)
        self.key = key


# ------------------------------------------------------------------------------------------ loading


def load_config(path: str | Path, overrides: typing.Sequence[str] = ()) -> Config | DamperConfig:
    """Read a YAML config, apply `--set dotted.key=value` overrides, validate. Raises InputError."""
    path = Path(path)
    source = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError("config file not found", source=source) from None
    except IsADirectoryError:
        raise InputError("is a directory, expected a YAML config file", source=source) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read config file ({exc.__class__.__name__}: {exc})", source=source) from None
    try:
        raw = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc)
        raise InputError(f"not valid YAML{where}: {problem}", source=source) from None
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise InputError(f"expected a mapping of sections at the top level, got {type(raw).__name__}", source=source)
    try:
        cfg = config_from_dict(apply_overrides(raw, overrides, source=source), source=source)
    except InputError as exc:
        _blame_override(raw, overrides, exc, source)
        raise
    if isinstance(cfg, DamperConfig):
        return _resolve_damper_paths(cfg, path)
    if cfg.road.file is not None and not Path(cfg.road.file).is_absolute():
        resolved = (path.parent / cfg.road.file).as_posix()
        cfg = cfg.model_copy(update={"road": cfg.road.model_copy(update={"file": resolved})})
        cfg._source = source
    return cfg


def _resolve_damper_paths(cfg: DamperConfig, path: Path) -> DamperConfig:
    """Data files named relative to the config file are resolved against its directory."""

    def resolve(name: str) -> str:
        return name if Path(name).is_absolute() else (path.parent / name).as_posix()

    source = cfg.source
    stages = tuple(
        s.model_copy(update={"file": resolve(s.file)}) if s.file is not None else s for s in cfg.identify.stages
    )
    cfg = cfg.model_copy(update={"identify": cfg.identify.model_copy(update={"stages": stages})})
    data = cfg.data
    if data is not None:
        update = {"validate_files": tuple(resolve(f) for f in data.validate_files)}
        if data.file is not None:
            update["file"] = resolve(data.file)
        cfg = cfg.model_copy(update={"data": data.model_copy(update=update)})
    cfg._source = source
    return cfg


def config_from_dict(raw: dict[str, Any], source: str = "<config>") -> Config | DamperConfig:
    """Validate a plain dict (e.g. parsed YAML) into a Config, or a DamperConfig when `system: damper`.
    Raises InputError naming the key."""
    root = DamperConfig if isinstance(raw, dict) and raw.get("system") == "damper" else Config
    try:
        cfg = root.model_validate(raw)
    except ValidationError as exc:
        raise InputError(_explain(exc, root), source=source) from None
    except _KeyedError as exc:  # raised from a validator outside pydantic's wrapping
        raise InputError(str(exc), source=source, key=exc.key) from None
    cfg._source = source
    return cfg


class Override(str):
    """A `dotted.key=value` override that remembers the option it came from (`--runs`), for error messages;
    a plain string is a `--set` line."""

    option: str | None = None

    def __new__(cls, text: str, option: str | None = None):
        self = super().__new__(cls, text)
        self.option = option
        return self


def _blame_override(raw: dict[str, Any], overrides: typing.Sequence[str], error: InputError, source: str) -> None:
    """When the overrides break a valid config, raise `error` naming the option of the override after the last
    valid state (`--set noise.levle=0.1: ...`); return when no state validates (the file's error stands)."""
    for i in reversed(range(len(overrides))):
        try:
            config_from_dict(apply_overrides(raw, overrides[:i], source=source), source=source)
        except InputError:
            continue
        item = overrides[i]
        option = getattr(item, "option", None) or f"--set {item}"
        raise InputError(error.detail, source=option, key=error.key) from None


def apply_overrides(raw: dict[str, Any], overrides: typing.Sequence[str], source: str = "<config>") -> dict[str, Any]:
    """Return a copy of `raw` with each `dotted.key=value` applied; values are parsed as YAML scalars/lists."""
    out = json.loads(json.dumps(raw, default=str))  # deep copy of plain data
    for item in overrides:
        if "=" not in item:
            raise InputError(f"--set expects dotted.key=value, got '{item}'", source=source)
        key, _, text = item.partition("=")
        key = key.strip()
        parts = key.split(".")
        if not key or any(not p for p in parts):
            raise InputError(f"--set expects dotted.key=value, got '{item}'", source=source)
        try:
            value = yaml.safe_load(text) if text.strip() else None
        except yaml.YAMLError:
            raise InputError(f"--set {key}: cannot parse value '{text}'", source=source) from None
        node = out
        for depth, part in enumerate(parts[:-1]):
            child = node.get(part)
            if child is None:
                child = node[part] = {}
            if not isinstance(child, dict):
                where = ".".join(parts[: depth + 1])
                raise InputError(f"--set {key}: '{where}' is a value, not a section", source=source)
            node = child
        node[parts[-1]] = value
    return out


# ------------------------------------------------------------------------------------------ errors


def _did_you_mean(word: str, choices: typing.Iterable[str]) -> str:
    close = difflib.get_close_matches(word, list(choices), n=1, cutoff=0.5)
    if not close:
        lowered = {c.lower(): c for c in choices}
        if word.lower() in lowered:
            close = [lowered[word.lower()]]
    return f"; did you mean '{close[0]}'?" if close else ""


def _described_as(word: str, model: type[BaseModel] | None) -> str:
    """Suggest the first field whose description mentions `word` (e.g. 'mass' -> 'm')."""
    if model is None or len(word) < 3:
        return ""
    for name, field in model.model_fields.items():
        text = (field.description or "").lower().replace("(", " ").replace(")", " ")
        if word.lower().replace("_", " ") in text:
            return f"; did you mean '{name}' ({field.description})?"
    return ""


def _model_at(loc: tuple, root: type[BaseModel] | None = None) -> type[BaseModel] | None:
    """The pydantic model class that validates the mapping at `loc` inside a Config (None if not a model)."""
    model: Any = Config if root is None else root
    for part in loc:
        if not (isinstance(model, type) and issubclass(model, BaseModel)) or part not in model.model_fields:
            return None
        model = _unwrap_model(model.model_fields[part].annotation)
    return model if isinstance(model, type) and issubclass(model, BaseModel) else None


def _unwrap_model(annotation: Any) -> Any:
    origin = typing.get_origin(annotation)
    if origin in (Union, types.UnionType):
        for arg in typing.get_args(annotation):
            if isinstance(arg, type) and issubclass(arg, BaseModel):
                return arg
    return annotation


BOUND_WORDS = {"ge": "at least", "gt": "greater than", "le": "at most", "lt": "less than"}


def _explain(exc: ValidationError, root: type[BaseModel] | None = None) -> str:
    """Turn pydantic's errors into one paragraph: each names its dotted key and what was expected."""
    lines = []
    for err in exc.errors(include_url=False):
        loc = tuple(p for p in err["loc"])
        key = ".".join(str(p) for p in loc)
        kind = err["type"]
        ctx_error = (err.get("ctx") or {}).get("error")
        if isinstance(ctx_error, _KeyedError):
            lines.append(f"'{ctx_error.key}': {ctx_error}")
            continue
        if kind == "extra_forbidden":
            parent = _model_at(loc[:-1], root)
            known = [f.alias or n for n, f in parent.model_fields.items()] if parent else []
            hint = _did_you_mean(str(loc[-1]), known) or _described_as(str(loc[-1]), parent)
            listing = f" (known keys: {', '.join(known)})" if known and not hint else ""
            lines.append(f"'{key}': unknown key{hint}{listing}")
        elif kind == "missing":
            lines.append(f"'{key}': required key is missing")
        elif kind == "literal_error":
            lines.append(f"'{key}': {err['msg'].replace('Input should be', 'expected')}, got {err['input']!r}")
        else:
            msg = err["msg"].removeprefix("Value error, ")
            msg = msg.replace("Input should be", "expected")
            bound = {k: v for k, v in (err.get("ctx") or {}).items() if k in BOUND_WORDS}
            if kind in ("greater_than_equal", "greater_than", "less_than_equal", "less_than") and bound:
                ((name, limit),) = bound.items()
                msg = f"must be {BOUND_WORDS[name]} {limit}"
            shown = "" if kind.startswith("value_error") or kind.startswith("assertion") else f", got {err['input']!r}"
            if key:
                lines.append(f"'{key}': {msg}{shown}")
            else:
                lines.append(f"{msg}{shown}")
    return "; ".join(lines)


def scaled_bounds(
    values: typing.Mapping[str, float], names: typing.Sequence[str], low: float = 0.1, high: float = 10.0
) -> dict[str, tuple[float, float]]:
    """Bounds by scaling the starting values (the paper's choice), with a symmetric range for values near 0."""
    out = {}
    for n in names:
        v = float(values[n])
        out[n] = (min(low * v, high * v), max(low * v, high * v)) if abs(v) > 1e-12 else (-1.0, 1.0)
    return out


def flatten(node, prefix: str = "") -> dict[str, object]:
    """A nested mapping as dotted keys -> leaf values (an empty mapping stays a leaf)."""
    if isinstance(node, dict):
        out: dict[str, object] = {}
        for key, value in node.items():
            out.update(flatten(value, f"{prefix}{key}."))
        return out or {prefix[:-1]: {}}
    return {prefix[:-1]: node}
