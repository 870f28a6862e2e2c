"""The package's one unit table: for each quantity, the unit names a file or a config may give and their factors to
SI (g is standard gravity, ISO 80000-3). Logger files, bench files and configs all read units through it; `Unit` marks
the SI unit of a parameter where it is declared."""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from .errors import InputError
from .hints import did_you_mean

UNITS: dict[str, dict[str, float]] = {
    "time": {"s": 1.0, "ms": 1e-3},
    "displacement": {"m": 1.0, "mm": 1e-3, "cm": 1e-2, "in": 0.0254},
    "velocity": {"m/s": 1.0, "mm/s": 1e-3, "cm/s": 1e-2, "in/s": 0.0254},
    "force": {"N": 1.0, "kN": 1e3, "lbf": 4.4482216152605, "lb": 4.4482216152605, "kip": 4448.2216152605},
    "control": {"1": 1.0, "fraction": 1.0, "%": 0.01, "percent": 0.01, "V": 1.0, "A": 1.0},
    # quantities of vehicle logger channels (io.read); g is standard gravity (ISO 80000-3)
    "acceleration": {"m/s^2": 1.0, "m/s2": 1.0, "m/s²": 1.0, "mm/s^2": 1e-3, "g": 9.80665},
    "angle": {"rad": 1.0, "deg": math.pi / 180, "°": math.pi / 180},
    "angular velocity": {"rad/s": 1.0, "deg/s": math.pi / 180, "°/s": math.pi / 180},
}


# One unit name -> its factor to SI, over all quantities of core.units.UNITS (no unit name means two things there).
SI_FACTORS: dict[str, float] = {unit: f for table in UNITS.values() for unit, f in table.items()}


def unit_factor(unit: str, source: str, channel: str) -> float:
    """The factor that turns `unit` into SI ('' is SI); InputError naming the file, the channel and the known units."""
    unit = unit.strip()
    if not unit:
        return 1.0
    if unit in SI_FACTORS:
        return SI_FACTORS[unit]
    raise InputError(
        f"{channel}: unknown unit '{unit}'{did_you_mean(unit, SI_FACTORS)}; known units: {', '.join(SI_FACTORS)}",
        source=source,
    )


# ------------------------------------------------------------------------------------------ units of parameters


@dataclass(frozen=True)
class Unit:
    """The SI unit of a config value, declared beside its type (``Annotated[float, Unit("kg")]``), so that every
    table, JSON and results file reads a parameter's unit from where the parameter is declared."""

    name: str


def declared_unit(metadata: Iterable[object]) -> str | None:
    """The unit a field's metadata declares (a pydantic FieldInfo's `metadata`), None when it declares none."""
    return next((m.name for m in metadata if isinstance(m, Unit)), None)
