"""The identified car (or damper) as a config (`--save-config FILE.yaml`, SPEC section 6): the input config, after
its `--set` overrides, with the identified values in place, each with a comment giving its 95 % interval and the
run it came from, so that `vehid simulate FILE.yaml` and `vehid identify FILE.yaml` continue from it.

The file is written fresh from the config's own structure (PyYAML drops comments and ruamel is not a dependency):
every key the user wrote is kept in order, defaults stay unwritten, the original's leading comment block is kept,
and comments are generated for each value that changed. Files the config names relative to itself are re-expressed
relative to the new file. Which config key holds which identified parameter is the system's config class's
(`SystemConfig.edits_for`); a run that started at random starts at the config (`identify.start: auto`) on measured
data, so that identifying again from the saved config starts at the estimate (the bounds, factors of the configured
values, are then centred on it).
"""

from __future__ import annotations

import copy
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from ..core.errors import InputError
from ..core.files import atomic_path, read_text
from . import apply_overrides, config_from_dict, load_config
from .common import ConfigEdit, SystemConfig
from .safe_yaml import load_yaml


@dataclass(frozen=True)
class Identified:
    """What a run found, for the config: values by parameter name (SI units), their 95 % intervals (None: unknown,
    or the estimate sits on a bound of its search box: `at_bound`), and where they came from (one line)."""

    values: Mapping[str, float]
    ci95: Mapping[str, tuple[float, float] | None]
    provenance: str
    at_bound: Sequence[str] = ()
    label: str = ""  # the run in a few words, for each value's comment (the data file and the date)
    notes: Mapping[str, str] = field(default_factory=dict)  # per value: other intervals, marked (misfit, model unc.)


def save_config(
    source: str | Path, overrides: Sequence[str], found: Identified, target: str | Path, *, command: str
) -> Path:
    """Write `source` (with `overrides`) and the identified values in place to `target` (YAML, atomically); the
    result is validated before it is written. Returns the target."""
    source, target = Path(source), Path(target)
    resolved = load_config(source, overrides)  # every error of the input config, as `identify` reports it
    text = read_text(source, "config file", "a YAML config file")
    raw = apply_overrides(load_yaml(text, str(source)) or {}, overrides, source=str(source))
    cfg = config_from_dict(copy.deepcopy(raw), source=str(source))
    _relocate(raw, _dump(cfg), _dump(resolved), target.resolve().parent)
    comments: dict[tuple[str, ...], str] = {}
    for edit in cfg.edits_for(found.values):
        _put(raw, edit.key, edit.value)
        comments[tuple(edit.key.split("."))] = _comment(edit, found, cfg.unit(edit.name) if edit.name else "")
    if cfg.identify.start == "random":
        _put(raw, "identify.start", "auto")
        comments[("identify", "start")] = "was random: on measured data the fit now starts at the values above"
    try:
        config_from_dict(copy.deepcopy(raw), source=str(target))
    except InputError as exc:
        raise InputError(f"the identified values make an invalid config: {exc.detail}", source=str(target)) from None
    header = [
        f"# {command} --save-config: {source.name} with the identified values in place (SPEC section 6)",
        f"# from {found.provenance}",
        "# each changed value carries its 95 % interval; the rest is the input config after its --set overrides",
    ]
    original = _leading_comments(text)
    body = "\n".join(header + (["#", *original] if original else []) + _emit(raw, comments)) + "\n"
    with atomic_path(target) as tmp:
        Path(tmp).write_text(body)
    return target


def _comment(edit: ConfigEdit, found: Identified, unit: str = "") -> str:
    """The comment on an identified value: where it came from and its 95 % interval, in the parameter's unit."""
    if edit.name is None:
        return edit.note
    if edit.name in found.at_bound:
        ci = "AT A BOUND of the search box (the optimum lies beyond it: no interval)"
    else:
        pair = found.ci95.get(edit.name)
        ok = pair is not None and all(math.isfinite(v) for v in pair)
        unit_text = f" {unit}" if unit and unit != "-" else ""
        ci = f"95 % interval [{pair[0]:.6g}, {pair[1]:.6g}]{unit_text}" if ok else "95 % interval unknown"
    value = "" if edit.key.endswith(edit.name) else f"{edit.name} = {found.values[edit.name]:.6g}, "
    run = f" ({found.label})" if found.label else ""
    other = found.notes.get(edit.name)
    return f"identified{run}: {value}{ci}" + (f"; {other}" if other else "") + (f"; {edit.note}" if edit.note else "")


def _dump(cfg: SystemConfig) -> dict:
    return cfg.model_dump(mode="json", exclude_none=True, by_alias=True)


def _relocate(raw: Any, plain: Any, resolved: Any, directory: Path) -> None:
    """Where the config's resolution changed a string (a file named relative to the config), write it relative to
    the new file's directory instead."""
    if isinstance(raw, dict) and isinstance(plain, dict) and isinstance(resolved, dict):
        items = [(k, k) for k in raw if k in plain and k in resolved]
    elif isinstance(raw, list) and isinstance(plain, list | tuple) and isinstance(resolved, list | tuple):
        items = [(i, i) for i in range(min(len(raw), len(plain), len(resolved)))]
    else:
        return
    for k, _ in items:
        a, b = plain[k], resolved[k]
        if isinstance(raw[k], str) and isinstance(a, str) and isinstance(b, str) and a != b:
            raw[k] = Path(os.path.relpath(Path(b).resolve(), directory)).as_posix()
        else:
            _relocate(raw[k], a, b, directory)


def _put(raw: dict, key: str, value: Any) -> None:
    """Set a dotted key, creating the sections on the way (a section given as null becomes a mapping)."""
    parts = key.split(".")
    node = raw
    for part in parts[:-1]:
        if not isinstance(node.get(part), dict):
            node[part] = {}
        node = node[part]
    node[parts[-1]] = float(value) if isinstance(value, int | float) and not isinstance(value, bool) else value


def _leading_comments(text: str) -> list[str]:
    """The comment lines a config starts with, less the header of an earlier --save-config (up to its "#")."""
    out = []
    for line in text.splitlines():
        if not line.startswith("#"):
            break
        out.append(line)
    if out and "--save-config:" in out[0]:
        out = out[out.index("#") + 1 :] if "#" in out else []
    return out


def _flow(value: Any) -> str:
    """One YAML value on one line (flow style: a list, a list of sensor specs, a scalar)."""
    text = yaml.safe_dump(value, default_flow_style=True, width=10**6, allow_unicode=True)
    return text.removesuffix("\n...\n").strip()


def _emit(node: dict, comments: Mapping[tuple[str, ...], str], path: tuple[str, ...] = (), indent: int = 0) -> list:
    """YAML lines of a mapping, block style for nested mappings, each commented key's comment on its line."""
    lines, pad = [], " " * indent
    for key, value in node.items():
        here = (*path, str(key))
        note = comments.get(here)
        tail = f"  # {note}" if note else ""
        if isinstance(value, dict) and value:
            lines.append(f"{pad}{_flow(key)}:{tail}")
            lines += _emit(value, comments, here, indent + 2)
        else:
            lines.append(f"{pad}{_flow(key)}: {_flow(value)}{tail}")
    return lines
