"""Systems under test behind one seam (`System`): the full car on a road, a damper on a test bench.

`build_system(config, data_file)` picks the system a config describes; `SYSTEMS` maps the results file's
`system` attribute back to its class (to read what the system added to a campaign).
"""

from __future__ import annotations

from pathlib import Path

from ..config import AnyConfig, DamperConfig
from ..core.errors import InputError
from .base import Box, Simulated, System
from .damper.system import DamperSystem, Findings
from .vehicle.system import VehicleSystem

SYSTEMS: dict[str, type[System]] = {VehicleSystem.name: VehicleSystem, DamperSystem.name: DamperSystem}
SIMULATION_SUFFIXES = tuple(dict.fromkeys(s for c in SYSTEMS.values() for s in c.simulation_suffixes))


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
    cls = system_class(config)
    target = Path(target)
    if target.suffix.lower() not in cls.simulation_suffixes:
        raise InputError(
            f"a {cls.name} simulation is written as {', '.join(cls.simulation_suffixes)}, not '{target.suffix}'",
            source=str(target),
        )
    return cls.write_simulation(config, target, seed, road, origin)


__all__ = [
    "SIMULATION_SUFFIXES", "SYSTEMS", "Box", "DamperSystem", "Findings", "Simulated", "System", "VehicleSystem",
    "build_system", "system_class", "write_simulation",
]  # fmt: skip
