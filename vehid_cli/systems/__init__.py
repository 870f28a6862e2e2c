"""Systems under test behind one seam (`System`): the full car on a road, a damper on a test bench.

`build_system(config, data_file)` picks the system a config describes; `SYSTEMS` maps the results file's
`system` attribute back to its class (to read what the system added to a campaign).
"""

from __future__ import annotations

from pathlib import Path

from ..config import AnyConfig, DamperConfig
from .base import Box, Simulated, System
from .damper import DamperSystem, Findings
from .vehicle import VehicleSystem

SYSTEMS: dict[str, type[System]] = {VehicleSystem.name: VehicleSystem, DamperSystem.name: DamperSystem}


def system_class(config: AnyConfig) -> type[System]:
    """The system a config describes (its `system` key)."""
    return DamperSystem if isinstance(config, DamperConfig) else VehicleSystem


def build_system(config: AnyConfig, data_file: str | Path | None = None) -> System:
    """The system a config describes, with its reference data (simulated, or read from `data_file`)."""
    return system_class(config)(config, data_file)


def write_simulation(
    config: AnyConfig, target: Path, seed: int, road: Path | None = None, origin: str = ""
) -> Simulated:
    """`vehid simulate`: the configured system simulated with run 0's noise stream of `seed`, written to `target`."""
    return system_class(config).write_simulation(config, Path(target), seed, road, origin)


__all__ = [
    "SYSTEMS", "Box", "DamperSystem", "Findings", "Simulated", "System", "VehicleSystem", "build_system",
    "system_class", "write_simulation",
]  # fmt: skip
