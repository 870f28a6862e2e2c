"""Experiment configuration: YAML -> validated, frozen pydantic models, with `--set` overrides.

One module per system around a shared `identify` vocabulary (`common.py`): `vehicle.py` (the full car) and
`damper.py` (a damper on a test bench). Every problem a user can make in a config is reported as an
:class:`InputError` that names the file (or the option) and the dotted key, with a did-you-mean for unknown keys
(exit status 2 on the command line).
"""

from __future__ import annotations

import types
import typing
from pathlib import Path
from typing import TYPE_CHECKING, Any, Union

from pydantic import BaseModel, ValidationError

from ..core.errors import InputError, clip
from ..core.files import read_text
from .common import Algorithm, IdentifyCommon, Start, SystemConfig, _did_you_mean, _KeyedError, flatten, scaled_bounds
from .safe_yaml import MAX_BYTES, MAX_DEPTH, load_yaml
from .vehicle import Bump, Config, Identify, Noise, RandomRoad, Road, Simulation, Vehicle

if TYPE_CHECKING:
    from .damper import DamperConfig
    from .half_car import HalfCarConfig
    from .quarter_car import QuarterCarConfig

    AnyConfig = Union[Config, DamperConfig, QuarterCarConfig, HalfCarConfig]  # noqa: UP007
else:  # at run time their common base: the other systems' config modules load at their first need (`_every`)
    AnyConfig = SystemConfig

# The config class of each system, by the `system` key of a config (a missing key is the car): CONFIGS. A system of
# its own registers its config here (`register_config`); nothing else in the package asks which system a config is.
_CONFIGS: dict[str, type[SystemConfig]] = {"vehicle": Config}
_DAMPER_NAMES = (
    "DAMPER_STRUCTURAL", "BenchSection", "DamperConfig", "DamperData", "DamperIdentify", "DamperNoise",
    "DamperSection", "DamperStage", "DataColumns", "DataUnits",
)  # fmt: skip


def _every() -> dict[str, type[SystemConfig]]:
    """CONFIGS: every system's config class by name. The car's is imported with this package, the others here at
    their first need: the damper's, the quarter and half car's modules (and the damper laws they compile) are
    start-up a car's command never uses (about 0.1 s of `vehid diagnose`)."""
    from .damper import DamperConfig
    from .half_car import HalfCarConfig
    from .quarter_car import QuarterCarConfig

    for name, cls in (("damper", DamperConfig), ("quarter_car", QuarterCarConfig), ("half_car", HalfCarConfig)):
        _CONFIGS.setdefault(name, cls)  # a config registered under the same name earlier stays
    return _CONFIGS


def __getattr__(name: str):
    """`CONFIGS` (every system's, `_every`) and the damper's sections, imported at their first use."""
    if name == "CONFIGS":
        return _every()
    if name in _DAMPER_NAMES:
        from . import damper

        return getattr(damper, name)
    if name in ("HalfCarConfig", "QuarterCarConfig"):
        return {"HalfCarConfig": _every()["half_car"], "QuarterCarConfig": _every()["quarter_car"]}[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def register_config(name: str, cls: type[SystemConfig]) -> None:
    """Make `system: <name>` configs validate as `cls`."""
    _CONFIGS[name] = cls


# ------------------------------------------------------------------------------------------ loading


def load_config(path: str | Path, overrides: typing.Sequence[str] = ()) -> Config | DamperConfig:
    """Read a YAML config, apply `--set dotted.key=value` overrides, validate. Raises InputError."""
    path = Path(path)
    source = str(path)
    text = read_text(path, "config file", "a YAML config file", limit=MAX_BYTES)
    raw = load_yaml(text, source)
    if raw is None:
        raw = {}
    if not isinstance(raw, dict):
        raise InputError(f"expected a mapping of sections at the top level, got {type(raw).__name__}", source=source)
    try:
        cfg = config_from_dict(apply_overrides(raw, overrides, source=source), source=source)
    except InputError as exc:
        _blame_override(raw, overrides, exc, source)
        raise
    return cfg.resolved(path)  # files the config names relative to itself


def config_from_dict(raw: dict[str, Any], source: str = "<config>") -> Config | DamperConfig:
    """Validate a plain dict (e.g. parsed YAML) into a Config, or a DamperConfig when `system: damper`.
    Raises InputError naming the key."""
    name = raw.get("system") if isinstance(raw, dict) else None
    if isinstance(name, str) and name not in _CONFIGS:
        _every()
    root = _CONFIGS.get(name, Config) if isinstance(name, str) else Config  # else Config's validation names the key
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
    out = _plain(raw)  # a deep copy of plain data, every key a string
    for item in overrides:
        option = getattr(item, "option", None) or "--set"
        if "=" not in item:
            raise InputError(f"{option} expects dotted.key=value, got {clip(repr(str(item)))}", source=source)
        key, _, text = item.partition("=")
        key = key.strip()
        parts = key.split(".")
        if not key or any(not p for p in parts) or len(parts) > MAX_DEPTH:
            raise InputError(f"{option} expects dotted.key=value, got {clip(repr(str(item)))}", source=source)
        what = f"{option} {clip(key)}: cannot parse the value as YAML"
        value = _plain(load_yaml(text, f"{option} {clip(key)}", what)) if text.strip() else None
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


def _plain(node: Any) -> Any:
    """A deep copy of parsed YAML as plain data: mappings with string keys (YAML's `1:`, `2001-01-01:` or `~:`
    become '1', '2001-01-01', 'None'), lists, and JSON's scalars; other scalars (a date, !!binary) as text."""
    if isinstance(node, dict):
        return {k if isinstance(k, str) else str(k): _plain(v) for k, v in node.items()}
    if isinstance(node, (list, tuple)):
        return [_plain(v) for v in node]
    return node if node is None or isinstance(node, (str, int, float, bool)) else str(node)


# ------------------------------------------------------------------------------------------ errors


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


def _range_of(loc: tuple, root: type[BaseModel] | None) -> str:
    """The whole range a numeric key takes, from its field's constraints ("in (0, 1e+06]"), '' when unknown."""
    while loc and isinstance(loc[-1], int):  # an item of a tuple: its field's items share one range
        loc = loc[:-1]
    parent = _model_at(loc[:-1], root)
    field = parent.model_fields.get(str(loc[-1])) if parent is not None else None
    if field is None and len(loc) >= 2:  # a value of a mapping (damper.parameters.c0): the mapping's value type
        parent = _model_at(loc[:-2], root)
        field = parent.model_fields.get(str(loc[-2])) if parent is not None else None
    if field is None:
        return ""
    found: dict[str, float] = {}
    for meta in field.metadata + [m for a in typing.get_args(field.annotation) for m in getattr(a, "__metadata__", ())]:
        for name in BOUND_WORDS:
            if getattr(meta, name, None) is not None:
                found[name] = getattr(meta, name)
        for inner in getattr(meta, "metadata", ()):
            for name in BOUND_WORDS:
                if getattr(inner, name, None) is not None:
                    found[name] = getattr(inner, name)
    low = ("[", found["ge"]) if "ge" in found else ("(", found["gt"]) if "gt" in found else None
    high = (found["le"], "]") if "le" in found else (found["lt"], ")") if "lt" in found else None
    if low is None or high is None:
        return ""
    return f"in {low[0]}{_number(low[1])}, {_number(high[0])}{high[1]}"


def _number(value: float) -> str:
    return str(value) if isinstance(value, int) else f"{value:g}"


def _explain(exc: ValidationError, root: type[BaseModel] | None = None) -> str:
    """Turn pydantic's errors into one paragraph: each names its dotted key and what was expected (a number's
    whole range), quoting at most a few hundred characters of what was given."""
    lines = []
    for err in exc.errors(include_url=False):
        loc = tuple(p for p in err["loc"])
        key = clip(".".join(str(p) for p in loc))
        kind = err["type"]
        ctx_error = (err.get("ctx") or {}).get("error")
        got = f", got {clip(repr(err.get('input')))}"
        if isinstance(ctx_error, _KeyedError):
            lines.append(f"'{ctx_error.key}': {ctx_error}")
            continue
        if kind == "extra_forbidden":
            parent = _model_at(loc[:-1], root)
            known = [f.alias or n for n, f in parent.model_fields.items()] if parent else []
            word = str(loc[-1])[:100]
            hint = _did_you_mean(word, known) or _described_as(word, parent)
            listing = f" (known keys: {', '.join(known)})" if known and not hint else ""
            lines.append(f"'{key}': unknown key{hint}{listing}")
        elif kind == "missing":
            lines.append(f"'{key}': required key is missing")
        elif kind == "literal_error":
            lines.append(f"'{key}': {clip(err['msg'].replace('Input should be', 'expected'))}{got}")
        else:
            msg = err["msg"].removeprefix("Value error, ")
            msg = clip(msg.replace("Input should be", "expected"), 1000)
            bound = {k: v for k, v in (err.get("ctx") or {}).items() if k in BOUND_WORDS}
            if kind in ("greater_than_equal", "greater_than", "less_than_equal", "less_than") and bound:
                ((name, limit),) = bound.items()
                msg = f"must be {_range_of(loc, root) or f'{BOUND_WORDS[name]} {limit}'}"
            shown = "" if kind.startswith("value_error") or kind.startswith("assertion") else got
            if key:
                lines.append(f"'{key}': {msg}{shown}")
            else:
                lines.append(f"{msg}{shown}")
    return "; ".join(lines)


__all__ = [
    "DAMPER_STRUCTURAL", "Algorithm", "AnyConfig", "BenchSection", "Bump", "Config", "DamperConfig", "DamperData",
    "DamperIdentify", "DamperNoise", "DamperSection", "DamperStage", "DataColumns", "DataUnits", "Identify",
    "IdentifyCommon", "Noise", "Override", "RandomRoad", "Road", "Simulation", "Start", "SystemConfig", "Vehicle",
    "CONFIGS", "apply_overrides", "config_from_dict", "register_config", "flatten", "load_config", "scaled_bounds",
]  # fmt: skip
