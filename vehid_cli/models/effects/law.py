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

import ast
import builtins
import hashlib
import importlib.util
import inspect
import os
import sys
import tempfile
import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from pathlib import Path

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


SLOT = "SLOT"  # in an effect's force, SLOT.<entry> stands for the slot of that entry of its params row
LAW_DIR_ENV = "VEHID_LAW_DIR"  # where the composed laws' sources are written (default: the user's cache)


class _Specialised(ast.NodeTransformer):
    """An effect's force body for one composed law: SLOT.<entry> -> the slot (an integer), its own local variables
    prefixed (two effects' locals never meet), the final `return f, damper` dropped."""

    def __init__(self, slots: Mapping[str, int], prefix: str, keep: set[str]):
        self.slots, self.prefix, self.keep = slots, prefix, keep

    def visit_Attribute(self, node: ast.Attribute):
        if isinstance(node.value, ast.Name) and node.value.id == SLOT:
            return ast.copy_location(ast.Constant(self.slots[node.attr]), node)
        return self.generic_visit(node)

    def visit_Name(self, node: ast.Name):
        if node.id not in self.keep and not hasattr(builtins, node.id) and node.id not in ("math", "np"):
            node.id = f"{self.prefix}{node.id}"
        return node


def _body(effect: Effect, slots: Mapping[str, int]) -> list[str]:
    """The lines of `effect.force`'s body specialised to `slots` (module doc of base.py: the contract)."""
    fn = ast.parse(textwrap.dedent(inspect.getsource(effect.force))).body[0]
    args = {a.arg for a in fn.args.args}
    body = fn.body
    if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
        body = body[1:]  # its docstring
    if body and isinstance(body[-1], ast.Return):
        body = body[:-1]
    own = own_slots(effect, slots)
    prefix = "_" + "".join(w[0] for w in effect.name.split("_")) + f"{effect.order}_"
    tree = ast.Module([_Specialised(own, prefix, args).visit(node) for node in body], type_ignores=[])
    return [f"# {effect.name}", *ast.unparse(tree).splitlines()]


def _indent(lines: Sequence[str], level: int) -> str:
    return "\n".join(" " * (4 * level) + line for line in lines)


def _source(effects: Sequence[Effect], slots: Mapping[str, int], kind: str) -> str:
    """The Python source of a composed law: every effect's force body in `order`, in one function, as the car's
    struts (`kind` "strut") or the bench (`kind` "bench") use it."""
    ordered = sorted(effects, key=lambda e: e.order)
    head = ["import math", "", "import numpy as np", "", "from vehid_cli.core.jit import cached_njit", "", "",
            '@cached_njit(error_model="numpy")']  # fmt: skip
    if kind == "bench":
        bodies = [line for e in ordered if e.bench for line in _body(e, slots)]
        lines = [
            "def bench_effects(d, dd, z, p, f_out, zd):",
            '    """The bench effects around the damper\'s force: d = [x, v, F_damper, F_gas]."""',
            "    x, v, c, i = d[0], d[1], 0.0, 0",
            "    f = d[3]",
            "    damper = d[2]",
            _indent(bodies, 1),
            "    f_out[0] = f + damper",
            "    for k in range(1, f_out.shape[0]):",
            "        f_out[k] = 0.0",
        ]
        return "\n".join(head + lines) + "\n"
    suspension = [line for e in ordered if not e.tyre for line in _body(e, slots)]
    tyres = [line for e in ordered if e.tyre for line in _body(e, slots)]
    lines = [
        "def strut_effects(d, dd, z, p, f_out, zd):",
        '    """Every effect present in the row p: struts 0..3 suspension, 4..7 tyres (if any)."""',
        f"    for i in range({N_CORNERS}):",
        f"        x, v, c = d[i], dd[i], p[{slots['c']} + i]",
        "        f = 0.0",
        "        damper = c * v",
        _indent(suspension, 2),
        "        f_out[i] = f + damper - c * v",
        f"    for k in range({N_CORNERS}, f_out.shape[0]):",
        f"        x, v, c, i = d[k], dd[k], 0.0, k - {N_CORNERS}",
        "        f = 0.0",
        "        damper = 0.0",
        _indent(tyres, 2),
        "        f_out[k] = f",
    ]
    return "\n".join(head + lines) + "\n"


def _law_dir() -> Path:
    """Where composed laws are written: $VEHID_LAW_DIR, else the user's cache (a temporary directory when that
    cannot be written)."""
    given = os.environ.get(LAW_DIR_ENV)
    cache = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
    base = Path(given) if given else cache / "vehid" / "laws"
    try:
        base.mkdir(parents=True, exist_ok=True)
        return base
    except OSError:
        fallback = Path(tempfile.gettempdir()) / f"vehid-laws-{os.getuid()}"
        fallback.mkdir(parents=True, exist_ok=True)
        return fallback


def _compiled(source: str, name: str):
    """The law `name` of `source`, from a module written under its digest (numba caches it on disk by that file,
    and the kernel keys its time loops with it)."""
    digest = hashlib.sha256(source.encode()).hexdigest()[:20]
    path = _law_dir() / f"law_{digest}.py"
    if not path.exists() or path.read_text() != source:
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(source)
        os.replace(tmp, path)
    spec = importlib.util.spec_from_file_location(f"vehid_law_{digest}", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return getattr(module, name)


@cache
def strut_law(effects: tuple[Effect, ...]):
    """The car's composed law over `effects` (struts 0..3 suspension, 4..7 tyres if any)."""
    return _compiled(_source(effects, layout(effects), "strut"), "strut_effects")


@cache
def bench_law(effects: tuple[Effect, ...]):
    """The composed law around a damper on a test bench over the registry `effects` (those with `bench`): channels
    d = [x, v, F_damper, F_gas] (the stroke [m], its velocity [m/s], the declared damper model's force without its
    gas part [N], its gas force [N]); f_out[0] = F_gas + the effects on the damper's force + the parallel effects,
    with the formulas of the car's struts at corner 1's slots."""
    return _compiled(_source(effects, layout(effects), "bench"), "bench_effects")


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
