"""Faults of the measurement chain: a sensor mounted upside down, a channel in another unit than declared, two
connectors swapped, a channel on a delayed clock, a saturating sensor, held samples, a drifting bias, an offset. Each
is one module of this package defining `FAULT` (`base.Fault`: its check against the configured model's prediction and
the correction the closed loop fits); the package registers every module it holds, in `Fault.order`. Adding a fault
is adding one module."""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable

from .base import FAIL, OK, WARNING, Channel, Context, Correction, Fault, Finding, correlation

FAULTS: dict[str, Fault] = {}


def register(fault: Fault) -> Fault:
    """Add a fault (kept in `order`); its name must be new."""
    if fault.name in FAULTS:
        raise ValueError(f"a fault named '{fault.name}' is registered already")
    entries = sorted([*FAULTS.values(), fault], key=lambda f: (f.order, f.name))
    FAULTS.clear()
    FAULTS.update((f.name, f) for f in entries)
    return fault


def fault_of(name: str) -> Fault:
    """The fault of a candidate's fault name (``swap:<other>`` is the swap)."""
    return FAULTS[name.partition(":")[0]]


def correction_unit(name: str, channel_unit: Callable[[str], str]) -> str | None:
    """The SI unit of a correction of the measurement chain, ``sensor:<channel>:<param>`` (its fault's `unit`, the
    channel's own unit in place of '{channel}'); None when `name` is not one, '' for a fault not registered."""
    if not name.startswith("sensor:"):
        return None
    channel, _, param = name.removeprefix("sensor:").partition(":")
    fault = FAULTS.get(param.partition(":")[0])
    if fault is None:
        return ""
    return fault.unit.replace("{channel}", channel_unit(channel) or "?") if "{channel}" in fault.unit else fault.unit


for _info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
    if _info.name != "base":
        register(importlib.import_module(f"{__name__}.{_info.name}").FAULT)

__all__ = [
    "FAIL", "FAULTS", "OK", "WARNING", "Channel", "Context", "Correction", "Fault", "Finding", "correlation",
    "correction_unit", "fault_of", "register",
]  # fmt: skip
