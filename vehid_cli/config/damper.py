"""A damper on a test bench: the model, the bench (or measured files), the noise, the identification."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import ConfigDict, Field, model_validator

from ..core.units import UNITS
from ..models.bench import BENCH_QUANTITIES
from ..models.damper import MODELS, default_values
from ..models.effects import LIBRARY, bench_names, bound_violation
from .common import (
    PARAMETER_MAX,
    Algorithm,
    Factor,
    Finite,
    IdentifyCommon,
    NonNeg,
    Pos,
    Seed,
    Start,
    SystemConfig,
    _did_you_mean,
    _KeyedError,
    _Section,
    int_in,
    scaled_bounds,
    within,
)

DAMPER_STRUCTURAL = ("m", "nv", "nu")  # table sizes: set by damper.table, never identified
DamperValue = within(
    -PARAMETER_MAX, PARAMETER_MAX
)  # a damper parameter [SI]; each model's physical limits are checked beside it
BENCH_SAMPLES = 2_000_000  # samples of a synthetic bench history at most
BENCH_STEPS = 20_000_000  # integration steps of one simulated bench history (samples x substeps) at most


class DamperSection(_Section):
    """The damper model (Fleps-Dezasse section 3) and its parameter values [SI: N, m, s; u in 0..1]."""

    model: str = Field(description="viscous, bingham, gas_spring, bouc_wen, generalized_bouc_wen or force_map")
    table: tuple[Annotated[int, Field(ge=1, le=50)], ...] = Field(
        (), description="table shape: [m] nodes over u (generalized_bouc_wen), [nv, nu] (force_map)"
    )
    parameters: dict[str, DamperValue] = Field(
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
    amplitude: within(1e-6, 10) = Field(
        0.025, description="displacement amplitude [m] (stroke/2 for constant_velocity)"
    )
    frequency: within(0, 1e4, low_open=True) = Field(0.8, description="sine frequency [Hz]")
    velocity: within(0, 100, low_open=True) = Field(
        0.15, description="|velocity| of sawtooth and constant_velocity [m/s]"
    )
    cycles: within(0, 1e5, low_open=True) = Field(3.0, description="number of periods (sine, sawtooth)")
    dt: within(1e-7, 1) = Field(0.001, description="sampling step of the bench history [s]")
    control: Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)] = Field(
        0.0, description="control input u [0..1] (sine, constant_velocity; the base level of the sawtooth)"
    )
    steps: tuple[tuple[within(0, 1e6), within(0, 1)], ...] | None = Field(
        None, description="control steps [(time [s], u), ...] of the sawtooth; default the paper's 15-50-15 %"
    )
    substeps: Annotated[int, Field(ge=1, le=1000)] = Field(
        1, description="integration steps per sample: the integrator runs at dt / substeps"
    )

    @model_validator(mode="after")
    def _grid(self) -> BenchSection:
        if self.excitation == "sine":
            seconds = self.cycles / self.frequency
        elif self.excitation == "sawtooth":
            seconds = self.cycles * 4 * self.amplitude / self.velocity
        else:  # one slow stroke each way
            seconds = 4 * self.amplitude / self.velocity
        samples = seconds / self.dt
        if not samples >= 3:
            raise ValueError(
                f"the {self.excitation} lasts {seconds:.3g} s: fewer than 3 samples of dt = {self.dt:g} s "
                "(more 'bench.cycles', a smaller 'bench.dt', a slower motion)"
            )
        if samples > BENCH_SAMPLES:
            raise ValueError(
                f"the {self.excitation} holds {samples:.3g} samples of dt = {self.dt:g} s; keep it below "
                f"{BENCH_SAMPLES:,} (a larger 'bench.dt', fewer 'bench.cycles', a faster motion)"
            )
        if samples * self.substeps > BENCH_STEPS:
            raise ValueError(
                f"the {self.excitation} takes {samples * self.substeps:.3g} integration steps ({samples:.3g} samples "
                f"x {self.substeps} substeps); keep it below {BENCH_STEPS:,}"
            )
        return self


class DataColumns(_Section):
    """Column names of a bench file; velocity is differentiated from displacement and control is 0 when absent."""

    time: str = "t"
    displacement: str = "x"
    force: str = "force"
    velocity: str | None = None
    control: str | None = None


class DataUnits(_Section):
    """Units of the columns (see vehid_cli.core.units.UNITS); a unit left out is the one the file declares (MDF4
    channel unit, HDF5 `unit` attribute), else the SI default below."""

    time: str = "s"
    displacement: str = "m"
    force: str = "N"
    velocity: str = "m/s"
    control: str = "1"


class DamperData(_Section):
    """Measured bench runs: the training file, its columns and units, and held-out validation files."""

    file: str | None = Field(
        None,
        description="training run: CSV (numeric or ISO 8601 time stamps, jitter resampled), MDF4 (.mf4), MAT "
        "(v5/v7.3) or HDF5 (.h5), read by vehid_cli.io.read; relative paths are relative to the config",
    )
    columns: DataColumns = DataColumns()
    units: DataUnits = DataUnits()
    window: tuple[NonNeg, Pos] | None = Field(None, description="use only start <= t < stop [s] of each file")
    decimate: Annotated[int, Field(ge=1, le=1000)] = Field(1, description="keep every n-th sample (for speed)")
    sample_rate: Pos | None = Field(
        None,
        description="nominal sampling rate [Hz] of files whose time column was printed with too few digits to be "
        "uniform: time is rebuilt as t0 + k / rate after checking it increases and agrees within 5 %",
    )
    variable: str | None = Field(
        None, description="the MAT struct (or HDF5 group) holding the channels, when the file has more than one"
    )
    resample: bool = Field(
        True,
        description="put channels at different rates or with jittered time stamps on one grid (io.read.read_record); "
        "false: read the samples as they are, and such a file is an error",
    )
    validate_files: tuple[str, ...] = Field((), alias="validate", description="held-out runs, same columns")

    model_config = ConfigDict(extra="forbid", frozen=True, strict=False, populate_by_name=True)

    @model_validator(mode="after")
    def _window(self) -> DamperData:
        for role in BENCH_QUANTITIES:
            table = UNITS[role]
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

    level: within(0, 10) = Field(0.0, description="0.02 = 2 %")


class DamperStage(_Section):
    """One stage of the step-by-step identification (Fleps-Dezasse section 4.2): its unknowns, fitted on its
    own experiment: a bench excitation (synthetic data) or a measured file."""

    name: str
    unknowns: Annotated[tuple[str, ...], Field(min_length=1)]
    bench: BenchSection | None = Field(None, description="the excitation of this stage (synthetic data)")
    file: str | None = Field(None, description="the measured run of this stage (relative to the config)")


class DamperIdentify(IdentifyCommon):
    """What to identify and how (common.IdentifyCommon; cost J, Fleps-Dezasse Eq. 7), with the damper's defaults,
    the real-time check's step and the stages of a step-by-step fit."""

    bounds: tuple[Factor, Factor] = Field((0.1, 10.0), description="search range as factors of the configured values")
    algorithm: Algorithm = Algorithm(name="nelder-mead", population=20, iterations=100)
    runs: int_in(1, 100_000) = 10
    seed: Seed = 2013
    start: Start = Field("auto", description="as for the car; auto: random for synthetic data, config for files")
    realtime_dt: within(1e-7, 1) = Field(0.001, description="step of the real-time check (fixed-step RK4) [s]")
    stages: tuple[DamperStage, ...] = Field(
        (),
        description="step-by-step identification: stages in order, each starting from what the previous found "
        "(e.g. gas force on a slow stroke, then the model per control input on sines, then lag and delays on "
        "the sawtooth); their unknowns together are identify.unknowns",
    )


class DamperConfig(SystemConfig):
    """A damper on a test bench: the model, the bench (or measured files), the noise, the identification."""

    system: Literal["damper"]
    damper: DamperSection
    bench: BenchSection = BenchSection()
    data: DamperData | None = None
    noise: DamperNoise = DamperNoise()
    identify: DamperIdentify

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
        for name, value in d.parameters.items():
            lo, hi = MODELS[d.model].bounds.get(name, (-np.inf, np.inf))
            if not lo <= value <= hi:
                raise _KeyedError(
                    f"damper.parameters.{name}", f"{value:g} is outside the physical range [{lo:g}, {hi:g}] of {name}"
                )
        for name in DAMPER_STRUCTURAL:
            if name in d.parameters and d.parameters[name] != self.values()[name]:
                raise _KeyedError(f"damper.parameters.{name}", f"'{name}' is the table size: set it in damper.table")
        for name in ident.unknowns:
            if name not in names:
                hint = _did_you_mean(name, names)
                raise _KeyedError("identify.unknowns", f"'{name}' is not a parameter of {d.model}{hint}")
            if name in DAMPER_STRUCTURAL:
                raise _KeyedError("identify.unknowns", f"'{name}' is a table size, not an identifiable parameter")
        ident.check_names()
        seen = set(ident.unknowns)
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
        ident.check_box(self.values(), self.search_box(), self._parameter_range)
        return self

    def _parameter_range(self, name: str) -> tuple[float, float]:
        """The physical range of an identifiable value: the model's limits or an effect's, within +-1e12."""
        if "." in name:
            effect, param = name.split(".", 1)
            p = next(p for p in LIBRARY[effect].params if p.name == param)
            low, high = p.lower, p.upper
        else:
            low, high = MODELS[self.damper.model].bounds.get(name, (-np.inf, np.inf))
        return max(low, -PARAMETER_MAX), min(high, PARAMETER_MAX)

    def _check_effects(self) -> None:
        """Bench effects exist, their parameters exist and lie in their physical bounds."""
        bench = bench_names()
        for name, params in self.damper.effects.items():
            if name not in bench:
                raise _KeyedError(
                    f"damper.effects.{name}",
                    f"'{name}' is not an effect on the bench{_did_you_mean(name, bench)} "
                    f"(known: {', '.join(bench)}; gas force and backlash are the model's k1, x0 and gap)",
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
        """All parameter values: the configured ones over the neutral defaults (models.damper.default_values)."""
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

    def resolved(self, path: Path) -> DamperConfig:
        """Data files (the run, the held-out runs, the stages' runs) named relative to the config file are resolved
        against its directory."""

        def resolve(name: str) -> str:
            return name if Path(name).is_absolute() else (path.parent / name).as_posix()

        stages = tuple(
            s.model_copy(update={"file": resolve(s.file)}) if s.file is not None else s for s in self.identify.stages
        )
        cfg = self._relocated({"identify": self.identify.model_copy(update={"stages": stages})})
        data = cfg.data
        if data is not None:
            update = {"validate_files": tuple(resolve(f) for f in data.validate_files)}
            if data.file is not None:
                update["file"] = resolve(data.file)
            cfg = cfg._relocated({"data": data.model_copy(update=update)})
        return cfg

    def data_runs(self) -> tuple[str, ...]:
        """The training run of data.file (its held-out runs are data.validate)."""
        return () if self.data is None or self.data.file is None else (self.data.file,)

    def related_runs(self, measured: bool) -> tuple[str, ...]:
        """The held-out runs (data.validate, when fitting measured data) and the stages' own runs."""
        held_out = tuple(str(p) for p in self.data.validate_files) if measured and self.data is not None else ()
        return held_out + tuple(str(s.file) for s in self.identify.stages if s.file is not None)
