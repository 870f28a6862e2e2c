"""What every system's config shares: the base of every section, value types, the algorithm, and one `identify`
vocabulary (unknowns, search box, algorithm, runs, seed, the evaluation budget, start, truth) with the checks
that mean the same for the car and the damper."""

from __future__ import annotations

import hashlib
import json
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, PrivateAttr

from ..core.errors import InputError
from ..core.hints import closest
from ..core.units import declared_unit
from ..models.effects import parameter_unit
from ..models.faults import correction_unit
from ..optimizers import ALGORITHMS, algorithm_class

Pos = Annotated[float, Field(gt=0, allow_inf_nan=False)]
NonNeg = Annotated[float, Field(ge=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]
SEED_MAX = 2**63 - 1  # seeds are stored as signed 64-bit integers


def within(low: float, high: float, *, low_open: bool = False) -> Any:
    """A finite number in [low, high] (`low_open`: in (low, high]): each numeric key's one range, broad enough for
    any vehicle or bench and narrow enough that the numerics stay finite (pydantic names the range on failure)."""
    lower = {"gt": low} if low_open else {"ge": low}
    return Annotated[float, Field(le=high, allow_inf_nan=False, **lower)]


def int_in(low: int, high: int) -> Any:
    """An integer in [low, high] (sizes, budgets and seeds, so that no count can ask for unbounded memory or time)."""
    return Annotated[int, Field(ge=low, le=high)]


Seed = int_in(0, SEED_MAX)
PARAMETER_MAX = 1e12  # |value| of any identified parameter, in SI units (a search range beyond it breaks numerics)
Factor = within(0, 1000, low_open=True)  # identify.bounds: a factor of a configured value
BumpShape = Literal["step", "cosine_step", "half_sine", "trapezoid"]  # road.bump.shape, design.shapes


class _Section(BaseModel):
    """Base of every config section: unknown keys are errors, values are immutable, ints become floats."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=False)


class _KeyedError(ValueError):
    """A validation error attached to a dotted key other than the one pydantic is validating."""

    def __init__(self, key: str, message: str):
        super().__init__(message)
        self.key = key


def _did_you_mean(word: str, choices: typing.Iterable[str]) -> str:
    """A config message's hint "; did you mean 'X'?" (core.hints.closest, a looser cutoff), else ''."""
    match = closest(word, choices, cutoff=0.5)
    return f"; did you mean '{match}'?" if match else ""


class Algorithm(_Section):
    """Identification algorithm and its budget."""

    name: str = Field("abc", description="an optimizer of vehid_cli/optimizers (SPEC section 3 names)")
    population: int_in(2, 10_000) = 20
    iterations: int_in(1, 1_000_000) = 50


def _start_alias(value: object) -> object:
    """`nominal` is the old name of `config` (vehicle configs before the vocabulary was shared)."""
    return "config" if value == "nominal" else value


Start = Annotated[Literal["auto", "random", "config"], BeforeValidator(_start_alias)]  # one vocabulary for all systems


def _check_algorithm(algorithm: Algorithm) -> None:
    """The algorithm exists (the optimizers' table of SPEC names is the one list) and its population suffices."""
    if algorithm.name not in ALGORITHMS:
        hint = _did_you_mean(algorithm.name, ALGORITHMS)
        known = "" if hint else f" (known: {', '.join(sorted(ALGORITHMS))})"
        raise _KeyedError("identify.algorithm.name", f"unknown algorithm '{algorithm.name}'{hint}{known}")
    cls = algorithm_class(algorithm.name)
    if algorithm.population < cls.min_population:
        raise _KeyedError(
            "identify.algorithm.population",
            f"{algorithm.name} needs a population of at least {cls.min_population}, got {algorithm.population}",
        )


class IdentifyCommon(_Section):
    """The identify keys every system shares, with one meaning each. Systems set their own defaults."""

    unknowns: Annotated[tuple[str, ...], Field(min_length=1)]
    bounds: tuple[Factor, Factor] = Field((0.7, 1.3), description="search range as factors of the configured values")
    limits: dict[str, tuple[Finite, Finite]] = Field(
        default_factory=dict, description="absolute search range per unknown [SI], overriding 'bounds'"
    )
    algorithm: Algorithm = Algorithm()
    runs: int_in(1, 100_000) = 30
    seed: Seed = 2015
    budget: int_in(1, 10**9) | None = Field(
        None,
        description="model evaluations per run (per stage for a staged damper fit), honoured exactly; default "
        "population x iterations",
    )
    start: Start = Field(
        "random",
        description="where a run starts: random (a random start from the run's stream), config (the configured "
        "values), auto (random for simulated data, config for measured data)",
    )
    truth: Literal["auto", "config", "none"] = Field(
        "auto", description="are the configured values the truth? auto: yes for simulated data, no for measured data"
    )

    def check_names(self) -> None:
        """Each unknown once, a known algorithm with a large enough population, limits for unknowns only, the
        bounds' factors in order."""
        seen: set[str] = set()
        for name in self.unknowns:
            if name in seen:
                raise _KeyedError("identify.unknowns", f"'{name}' is listed twice")
            seen.add(name)
        _check_algorithm(self.algorithm)
        for name in self.limits:
            if name not in self.unknowns:
                raise _KeyedError(
                    f"identify.limits.{name}", f"'{name}' is not one of the unknowns {list(self.unknowns)}"
                )
        lo_f, hi_f = self.bounds
        if not lo_f < hi_f:
            raise _KeyedError("identify.bounds", f"lower factor {lo_f:g} must be below upper factor {hi_f:g}")

    def box(self, values: Mapping[str, float]) -> dict[str, tuple[float, float]]:
        """Search range of each unknown [SI]: 'limits' where given, else 'bounds' x its configured value in
        `values` (ordered low, high: a negative value turns the factors round)."""
        lo_f, hi_f = self.bounds
        box = {n: self.limits.get(n, (lo_f * values[n], hi_f * values[n])) for n in self.unknowns}
        return {n: (min(lo, hi), max(lo, hi)) for n, (lo, hi) in box.items()}

    def check_box(
        self,
        values: Mapping[str, float],
        box: Mapping[str, tuple[float, float]],
        ranges: typing.Callable[[str], tuple[float, float] | None] = lambda name: None,
    ) -> None:
        """Every unknown's search range is a range, holds its configured value and stays inside the parameter's
        physical range (`ranges(name)`, None: any finite value), so that no candidate breaks the numerics."""
        for name, (lo, hi) in box.items():
            key = f"identify.limits.{name}" if name in self.limits else "identify.bounds"
            if not lo < hi:
                raise _KeyedError(key, f"lower limit {lo:g} must be below upper limit {hi:g}")
            low, high = ranges(name) or (-PARAMETER_MAX, PARAMETER_MAX)
            if not low <= lo <= hi <= high:
                raise _KeyedError(
                    key, f"the search range [{lo:g}, {hi:g}] of '{name}' leaves its physical range [{low:g}, {high:g}]"
                )
            if not lo <= values[name] <= hi:
                raise _KeyedError(
                    key, f"the search range [{lo:g}, {hi:g}] of '{name}' excludes its configured value {values[name]:g}"
                )


@dataclass(frozen=True)
class ConfigEdit:
    """One change `--save-config` makes to a config: the dotted key, its new value, the identified parameter it
    carries (its interval goes in the key's comment; None: a consequence of one, e.g. a2 when the wheelbase is kept)
    and a note saying why."""

    key: str
    value: Any
    name: str | None = None
    note: str = ""


class SystemConfig(_Section):
    """Base of a whole config (a car, a damper): where it was read from, its YAML and its digest."""

    _source: str = PrivateAttr(default="<config>")

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

    def unit(self, name: str) -> str:
        """The SI unit of the identifiable parameter `name`, read where the parameter is declared: a correction of
        the measurement chain (``sensor:<channel>:<param>``: its fault's `unit`), an effect's own declaration
        (``<effect>.<param>``), else the type of the field of that name in one of the config's sections
        (core.units.Unit); '' when none is declared. A system whose parameters are declared elsewhere (the damper's
        model rows) extends this."""
        sensor = correction_unit(name, self.channel_unit)
        if sensor is not None:
            return sensor
        if "." in name:
            return parameter_unit(*name.split(".", 1))
        for key in type(self).model_fields:
            section = getattr(self, key)
            field = type(section).model_fields.get(name) if isinstance(section, BaseModel) else None
            unit = None if field is None else declared_unit(field.metadata)
            if unit is not None:
                return unit
        return ""

    def channel_unit(self, channel: str) -> str:
        """The SI unit of a measured channel (for the corrections of the measurement chain); '' when unknown."""
        return ""

    def units(self, names: typing.Iterable[str]) -> dict[str, str]:
        """{name: SI unit} of parameters (`unit`): the one lookup tables, JSON and results files use."""
        return {n: self.unit(n) for n in names}

    def resolved(self, path: Path) -> SystemConfig:
        """The config with the files it names relative to its own file (`path`) resolved against that file's
        directory (a system with such files overrides this)."""
        return self

    def data_runs(self) -> tuple[str, ...]:
        """The measured runs the config names to identify from (empty: simulated data)."""
        return ()

    def related_runs(self, measured: bool) -> tuple[str, ...]:
        """Other files a campaign's results depend on (held-out runs, a stage's own run); `measured`: the campaign
        identifies from measured runs."""
        return ()

    def edits_for(self, values: Mapping[str, float]) -> list[ConfigEdit]:
        """The config keys that hold identified `values` (by parameter name, SI units), for `--save-config`; a
        system whose config can carry them overrides this."""
        raise InputError(f"--save-config: a {type(self).__name__} cannot hold identified values", source=self.source)

    def _relocated(self, update: dict[str, Any]) -> SystemConfig:
        """A copy with some sections replaced, keeping the source it was read from."""
        cfg = self.model_copy(update=update)
        cfg._source = self._source
        return cfg


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
