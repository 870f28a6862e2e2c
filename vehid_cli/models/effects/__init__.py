"""The effect library: nonlinear strut and tyre physics on top of the linear full car (SPEC section 5 names), and
around a damper on a test bench.

Each effect is one module of this package defining `EFFECT` (`base.Effect`: its parameters, defaults that make it
inactive, physical bounds, states, its compiled force, its candidate forms for the closed loop and the shapes its
force leaves in a residual); the package registers every module it holds, in `Effect.order`. Adding an effect is
adding one module (and its test); `register` adds one from elsewhere (a test's toy effect). The compiled laws of the
car's struts and of the bench are composed from the registry (`law.py`), so an effect present costs its own
arithmetic and an absent one a branch; deflections are measured from static equilibrium (SPEC section 1), so every
effect's force is zero at rest. Effects in parallel add; series elements (backlash, lag) act on the configured
damper in order (lag after backlash).
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Mapping

from numpy.typing import ArrayLike

from .base import BenchScale, CandidateForm, CarScale, Effect, Param, Shape
from .law import AXLE_OF_CORNER, N_CORNERS, EffectSet, bench_law, layout, rows_for, strut_law

AXLES = ("f", "r")
LIBRARY: dict[str, Effect] = {}  # name -> effect, in Effect.order


def register(effect: Effect) -> Effect:
    """Add an effect to the library (kept in `order`); its name must be new."""
    if effect.name in LIBRARY:
        raise ValueError(f"an effect named '{effect.name}' is registered already")
    entries = sorted([*LIBRARY.values(), effect], key=lambda e: (e.order, e.name))
    LIBRARY.clear()
    LIBRARY.update((e.name, e) for e in entries)
    return effect


def unregister(name: str) -> None:
    """Remove an effect from the library (a test's toy effect, after the test)."""
    del LIBRARY[name]


def _discover() -> None:
    """Register the EFFECT of every module of this package (but the base and the composed law)."""
    for info in sorted(pkgutil.iter_modules(__path__), key=lambda m: m.name):
        if info.name in ("base", "law"):
            continue
        module = importlib.import_module(f"{__name__}.{info.name}")
        register(module.EFFECT)


_discover()


def __getattr__(name: str):
    """Names that follow the registry: the composed laws and the name lists."""
    if name == "strut_effects":
        return strut_law(tuple(LIBRARY.values()))
    if name == "bench_effects":
        return bench_law(tuple(LIBRARY.values()))
    if name == "EFFECT_NAMES":
        return tuple(LIBRARY)
    if name == "BENCH_EFFECTS":
        return bench_names()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def bench_names() -> tuple[str, ...]:
    """The effects that act around a damper on a test bench (its own gas force and play are its model's k1, x0 and
    gap, models/damper.py)."""
    return tuple(n for n, e in LIBRARY.items() if e.bench)


def check_names(effects: Mapping[str, Mapping[str, object]]) -> None:
    """KeyError naming the first unknown effect or parameter."""
    for name, params in effects.items():
        if name not in LIBRARY:
            raise KeyError(f"unknown effect '{name}'")
        unknown = set(params) - set(LIBRARY[name].names())
        if unknown:
            raise KeyError(f"not parameters of {name}: {sorted(unknown)}")


def effect_rows(
    effects: Mapping[str, Mapping[str, ArrayLike]], cf: ArrayLike, cr: ArrayLike, batch: tuple[int, ...]
) -> EffectSet:
    """Params rows (P = prod(batch)) of the car's composed law for the present effects (values scalars or arrays of
    shape `batch`; missing parameters at their defaults) and the configured linear damping cf, cr [N s/m]."""
    check_names(effects)
    library = tuple(LIBRARY.values())
    rows, n_z = rows_for(LIBRARY, effects, cf, cr, batch)
    return EffectSet(rows=rows, n_z=n_z, tyres=any(LIBRARY[n].tyre for n in effects), law=strut_law(library))


def bench_effect_rows(effects: Mapping[str, Mapping[str, ArrayLike]], P: int) -> EffectSet:
    """Params rows of the bench's composed law for P candidates; effect parameters by their base names (``alpha``,
    not ``alpha_f``): one damper, so the per-axle pair carries the same value."""
    unknown = [e for e in effects if e not in bench_names()]
    if unknown:
        raise KeyError(f"not an effect on the test bench: {unknown} (bench effects: {', '.join(bench_names())})")
    per_axle = {}
    for name, given in effects.items():
        e = LIBRARY[name]
        values: dict[str, ArrayLike] = {}
        for key, value in given.items():
            p = e.param(key if key in e.names() else f"{key}_f")
            if p.per_axle:
                values[f"{p.name}_f"] = values[f"{p.name}_r"] = value
            else:
                values[p.name] = value
        per_axle[name] = values
    rows, n_z = rows_for(LIBRARY, per_axle, 0.0, 0.0, (P,))
    return EffectSet(rows=rows, n_z=n_z, tyres=False, law=bench_law(tuple(LIBRARY.values())))


def bench_lag_state(eset: EffectSet) -> int | None:
    """Index of the damper-lag state in a bench effect set's states (None without the lag)."""
    slots = layout(tuple(LIBRARY.values()))
    row = eset.rows[0]
    return int(row[slots["damper_lag:z"]]) if row[slots["damper_lag:on"]] != 0.0 else None


def bound_violation(effect: str, name: str, value: float) -> str | None:
    """Why `value` is outside the physical bounds of effect.name, or None if it is inside."""
    p = LIBRARY[effect].param(name)
    low_ok = value > p.lower if p.open_lower else value >= p.lower
    if low_ok and value <= p.upper:
        return None
    lo = "(" if p.open_lower else "["
    return f"{effect}.{name} = {value:g} {p.unit} is outside its physical range {lo}{p.lower:g}, {p.upper:g}]"


def parameter_unit(effect: str, name: str) -> str:
    """The SI unit an effect declares for its parameter `name` (per-axle ones with or without _f / _r: a damper on a
    bench names them plainly); '' for an unknown effect or parameter."""
    if effect not in LIBRARY:
        return ""
    return next((p.unit for p in LIBRARY[effect].params if name in (p.name, f"{p.name}_f", f"{p.name}_r")), "")


__all__ = [
    "AXLES", "AXLE_OF_CORNER", "LIBRARY", "N_CORNERS", "BenchScale", "CandidateForm", "CarScale", "Effect", "EffectSet",
    "Param", "Shape", "bench_effect_rows", "bench_lag_state", "bench_names", "bound_violation", "check_names",
    "effect_rows", "parameter_unit", "register", "unregister",
]  # fmt: skip
