"""Systems under test behind one seam (`System`): the full car on a road, a damper on a test bench.

`SYSTEMS` maps a config's (and a results file's) `system` name to its class; `register_system` adds one (a system
is one sub-package plus its config section, registered with `config.register_config`). `build_system(config,
data)` builds the system a config describes with its reference data; `write_simulation` and `diagnose_config`
are the library side of `vehid simulate` and `vehid diagnose`.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from ..config import AnyConfig, load_config
from ..core.errors import InputError
from ..core.progress import ProgressHook
from ..diagnose.checks import Checks
from ..identify.source import DataFiles, DataSource, as_paths
from .base import Box, Log, Simulated, System
from .vehicle.system import VehicleSystem

_SYSTEMS: dict[str, type[System]] = {VehicleSystem.name: VehicleSystem}  # SYSTEMS, the others once `_every` ran


def _every() -> dict[str, type[System]]:
    """SYSTEMS: every known system by name. The car's is imported with this module, the others here at their first
    need: their modules and the campaign and HDF5 machinery they pull in are start-up a car's command never uses
    (about 0.05-0.1 s of `vehid diagnose`)."""
    from .damper.system import DamperSystem
    from .half_car.system import HalfCarSystem
    from .quarter_car.system import QuarterCarSystem

    for cls in (DamperSystem, QuarterCarSystem, HalfCarSystem):
        _SYSTEMS.setdefault(cls.name, cls)  # a system registered under the same name earlier stays
    return _SYSTEMS


def __getattr__(name: str):
    """`SYSTEMS` (every system, `_every`) and the damper's classes, imported at first use."""
    if name == "SYSTEMS":
        return _every()
    if name in ("DamperSystem", "Findings"):
        from .damper.findings import Findings
        from .damper.system import DamperSystem

        return {"DamperSystem": DamperSystem, "Findings": Findings}[name]
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def register_system(cls: type[System]) -> type[System]:
    """Make a system known by its name (usable as a class decorator)."""
    _SYSTEMS[cls.name] = cls
    return cls


def simulation_suffixes() -> tuple[str, ...]:
    """Every file type some system's `vehid simulate` writes."""
    return tuple(dict.fromkeys(s for c in _every().values() for s in c.simulation_suffixes))


def system_class(config: AnyConfig) -> type[System]:
    """The system a config describes (its `system` key): the car's without importing the others."""
    cls = _SYSTEMS.get(config.system) or _every().get(config.system)
    if cls is None:
        raise InputError(
            f"no system '{config.system}' (known: {', '.join(_every())})", source=config.source, key="system"
        )
    return cls


def build_system(config: AnyConfig, data: DataFiles | DataSource = None) -> System:
    """The system a config describes, with its reference data: simulated, or the measured runs of `data` (else the
    config's own)."""
    return system_class(config)(config, DataSource.resolve(config, data))


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


def diagnose_config(
    config: str | Path,
    overrides: Sequence[str] = (),
    data: DataFiles = None,
    validate: Sequence[str | Path] = (),
    log: Log | None = None,
    progress: ProgressHook | None = None,
):
    """`vehid diagnose`: the config's system closes the loop on `data` (else the config's own runs), judged on the
    `validate` runs; the system's diagnosis defaults come before the user's `overrides`; `progress` hears of the
    loop's steps (stage, done, total)."""
    cfg = load_config(config, overrides)
    cls = system_class(cfg)
    if cls.diagnosis_defaults:
        cfg = load_config(config, [*cls.diagnosis_defaults, *overrides])
    return cls.diagnose(cfg, as_paths(data), as_paths(tuple(validate)), log, progress)


def check_config(config: str | Path, overrides: Sequence[str] = (), data: DataFiles = None) -> tuple[System, Checks]:
    """`vehid check`: every measured channel of `data` (else the config's runs) against the configured model."""
    cfg = load_config(config, overrides)
    system = build_system(cfg, data)
    if system.source.simulated:
        raise InputError("vehid check holds measured data against the model: give --data FILE (or data.files)",
                         source=str(config))  # fmt: skip
    found = system.checks()
    if found is None:
        raise InputError(f"vehid check has no checks for a {system.name} yet", source=str(config), key="system")
    return system, found


__all__ = [
    "SYSTEMS", "Box", "DamperSystem", "Findings", "Simulated", "System", "VehicleSystem", "build_system",
    "check_config", "diagnose_config", "register_system", "simulation_suffixes", "system_class", "write_simulation",
]  # fmt: skip
