"""Systems under test behind one seam (`System`): the full car on a road, a damper on a test bench.

`build_system(config, data_file)` picks the system a config describes; `SYSTEMS` maps the results file's
`system` attribute back to its class (to read what the system added to a campaign).
"""

from __future__ import annotations

from pathlib import Path

from ..config import AnyConfig, DamperConfig
from .base import Box, System
from .damper import DamperSystem, Findings
from .vehicle import VehicleSystem

SYSTEMS: dict[str, type[System]] = {VehicleSystem.name: VehicleSystem, DamperSystem.name: DamperSystem}


def build_system(config: AnyConfig, data_file: str | Path | None = None) -> System:
    """The system a config describes, with its reference data (simulated, or read from `data_file`)."""
    if isinstance(config, DamperConfig):
        return DamperSystem(config, data_file)
    return VehicleSystem(config, data_file)


__all__ = ["SYSTEMS", "Box", "DamperSystem", "Findings", "System", "VehicleSystem", "build_system"]
