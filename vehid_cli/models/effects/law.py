"""The compiled force laws composed from the registered effects: one for the car's struts, one around a damper on a
test bench, both of the kernel's shape ``law(d, dd, z, params, f_out, zd_out)``.

A params row holds, per candidate car, the configured linear damping c of the four corners, then for each effect
(in registry order) an 'on' flag, a state offset (stateful effects) and its parameters (four corner slots for a
per-axle one). Each effect's own force (`Effect.law`, built from its slots) is chained in `Effect.order`: the
parallel forces add in that order, series elements (play, lag) act on the damper's force in that order.

Struts of the car (kernel convention: forces [N] positive resisting positive deflection, like k d): 0..3 the
suspension of corners 1..4 (deflection d = G q_b - x_i, positive in extension), 4..7 the tyres (when a tyre effect
is present: deflection x_i - y_i). Force laws use ``error_model="numpy"``: an unstable candidate gives NaN or inf,
not an exception.
"""

from __future__ import annotations

import hashlib
import inspect
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

from .base import Effect

N_CORNERS = 4
AXLE_OF_CORNER = (0, 0, 1, 1)  # corners 1, 2 front; 3, 4 rear


def layout(effects: Sequence[Effect]) -> dict[str, int]:
    """Slot of every entry of a params row: the linear damping c (4 corners), then per effect an 'on' flag, a state
    offset (stateful effects) and its parameters (4 corner slots for per-axle ones); ':width' the row's length."""
    slots: dict[str, int] = {}
    k = 0

    def add(key: str, width: int) -> None:
        nonlocal k
        slots[key] = k
        k += width

    add("c", N_CORNERS)
    for e in effects:
        add(f"{e.name}:on", 1)
        if e.states:
            add(f"{e.name}:z", 1)
        for p in e.params:
            add(f"{e.name}.{p.name}", N_CORNERS if p.per_axle else 1)
    slots[":width"] = k
    return slots


def own_slots(effect: Effect, slots: Mapping[str, int]) -> dict[str, int]:
    """The slots an effect's `law` is built from: on, z (stateful), and its parameters by their base names."""
    out = {"on": slots[f"{effect.name}:on"]}
    if effect.states:
        out["z"] = slots[f"{effect.name}:z"]
    out.update({p.name: slots[f"{effect.name}.{p.name}"] for p in effect.params})
    return out


@numba.njit(inline="always")
def _nothing(x, v, c, i, p, z, zd, f, damper):  # pragma: no cover - compiled
    """The end of a chain: no effect."""
    return f, damper


def _then(first, second):
    """The compiled chain `first`, then `second`."""

    @numba.njit(inline="always", error_model="numpy")
    def both(x, v, c, i, p, z, zd, f, damper):  # pragma: no cover - compiled
        f, damper = first(x, v, c, i, p, z, zd, f, damper)
        return second(x, v, c, i, p, z, zd, f, damper)

    return both


def _chain(effects: Sequence[Effect], slots: Mapping[str, int]):
    """Every effect's force in `order`, one compiled function (the effects inlined)."""
    out = _nothing
    for e in sorted(effects, key=lambda e: e.order):
        out = _then(out, e.law(own_slots(e, slots)))
    return out


def _salt(effects: Sequence[Effect], slots: Mapping[str, int]) -> str:
    """What a composed law's compiled code depends on besides this file: each effect's module source and the slots
    (the kernel keys its on-disk cache of a law's time loop with it)."""
    h = hashlib.sha256(Path(__file__).read_bytes())
    for e in effects:
        module = inspect.getmodule(e.law)
        source = inspect.getsource(module) if module is not None else repr(e)
        h.update(f"{e.name} {e.order}\0".encode() + source.encode())
    h.update(repr(sorted(slots.items())).encode())
    return h.hexdigest()


@cache
def strut_law(effects: tuple[Effect, ...]):
    """The car's composed law over `effects` (struts 0..3 suspension, 4..7 tyres if any)."""
    slots = layout(effects)
    C = slots["c"]
    suspension = _chain([e for e in effects if not e.tyre], slots)
    tyres = _chain([e for e in effects if e.tyre], slots)

    @numba.njit(error_model="numpy")
    def strut_effects(d, dd, z, p, f_out, zd_out):  # pragma: no cover - compiled
        """Every effect present in the row p: struts 0..3 suspension, 4..7 tyres (if any)."""
        for i in range(N_CORNERS):
            x, v, c = d[i], dd[i], p[C + i]
            f, damper = suspension(x, v, c, i, p, z, zd_out, 0.0, c * v)
            f_out[i] = f + damper - c * v
        for i in range(N_CORNERS, f_out.shape[0]):
            f, _ = tyres(d[i], dd[i], 0.0, i - N_CORNERS, p, z, zd_out, 0.0, 0.0)
            f_out[i] = f

    strut_effects.cache_salt = _salt(effects, slots)
    return strut_effects


@cache
def bench_law(effects: tuple[Effect, ...]):
    """The composed law around a damper on a test bench over the registry `effects` (those with `bench`): channels
    d = [x, v, F_damper, F_gas] (the stroke [m], its velocity [m/s], the declared damper model's force without its
    gas part [N], its gas force [N]); f_out[0] = F_gas + the effects on the damper's force + the parallel effects,
    with the formulas of the car's struts at corner 1's slots."""
    slots = layout(effects)
    chain = _chain([e for e in effects if e.bench], slots)

    @numba.njit(error_model="numpy")
    def bench_effects(d, dd, z, p, f_out, zd_out):  # pragma: no cover - compiled
        """The bench effects present in the row p around the damper's force."""
        f, damper = chain(d[0], d[1], 0.0, 0, p, z, zd_out, d[3], d[2])
        f_out[0] = f + damper
        for i in range(1, f_out.shape[0]):
            f_out[i] = 0.0

    bench_effects.cache_salt = _salt(effects, slots)
    return bench_effects


@dataclass(frozen=True)
class EffectSet:
    """The effects of one simulation: which are present, their parameters for a batch, the kernel's sizes."""

    rows: NDArray  # (P, width) params rows of the composed law
    n_z: int  # internal states (all corners)
    tyres: bool  # the tyre struts are needed
    law: object  # the composed law the rows are laid out for


def rows_for(
    library: Mapping[str, Effect],
    effects: Mapping[str, Mapping[str, ArrayLike]],
    cf: ArrayLike,
    cr: ArrayLike,
    batch: tuple[int, ...],
) -> tuple[NDArray, int]:
    """Params rows (P = prod(batch)) of the present effects (values scalars or arrays of shape `batch`; missing
    parameters at their defaults) with the linear damping cf, cr [N s/m] of each car; and the number of states."""
    slots = layout(tuple(library.values()))
    P = int(np.prod(batch, dtype=int))

    def flat(value: ArrayLike) -> NDArray:
        return np.broadcast_to(np.asarray(value, dtype=float), batch).reshape(P)

    rows = np.zeros((P, slots[":width"]))
    c = (flat(cf), flat(cr))
    for i in range(N_CORNERS):
        rows[:, slots["c"] + i] = c[AXLE_OF_CORNER[i]]
    n_z = 0
    for name, given in effects.items():
        e = library[name]
        values = {**e.defaults(), **given}
        rows[:, slots[f"{name}:on"]] = 1.0
        if e.states:
            rows[:, slots[f"{name}:z"]] = n_z
            n_z += e.states * N_CORNERS
        for p in e.params:
            s = slots[f"{name}.{p.name}"]
            if p.per_axle:
                axle = (flat(values[f"{p.name}_f"]), flat(values[f"{p.name}_r"]))
                for i in range(N_CORNERS):
                    rows[:, s + i] = axle[AXLE_OF_CORNER[i]]
            else:
                rows[:, s] = flat(values[p.name])
    return rows, n_z
