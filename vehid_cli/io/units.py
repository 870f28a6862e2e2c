"""The units of logger channels: one unit name -> its factor to SI, over every quantity of `core.units.UNITS`, so a
channel's unit is named without its quantity ('g', 'mm', 'deg'); reading multiplies by the factor, writing divides."""

from __future__ import annotations

from ..core.errors import InputError
from ..core.units import UNITS
from .hints import did_you_mean

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
