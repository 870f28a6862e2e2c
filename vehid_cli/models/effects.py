"""The effect library: nonlinear strut and tyre physics on top of the linear full car (SPEC section 5 names).

Each effect has parameters (named per axle ``<name>_f`` / ``<name>_r`` where front and rear differ), defaults
that make it inactive (its strength parameter is zero) or typical (shape parameters), physical bounds, and a
number of internal states per corner. All effects of a config combine into ONE numba force law,
``strut_effects``, of the kernel's shape ``law(d, dd, z, params, f_out, zd_out)``: one params row per
candidate car holds every effect's slots; an effect not present costs one branch, a present effect whose
strength is zero adds exactly nothing.

Struts (kernel convention: forces [N] positive resisting positive deflection, like k d):

* 0..3, the suspension of corners 1..4: deflection d = D q = G q_b - x_i [m] (body point minus wheel,
  positive in extension = rebound), velocity dd [m/s];
* 4..7, the tyres (only when ``tyre_damping`` is present): deflection x_i - y_i [m], velocity xd_i - yd_i.

Deflections are measured from static equilibrium (SPEC section 1), so every effect's force is zero at rest.
The suspension effects (per corner, c the configured linear damping cf / cr of that corner [N s/m]):

* ``asymmetric_damping``: rebound and compression damping c + dc/2 and c - dc/2, blended by the smooth
  switch of Fleps-Dezasse Eq. 4-5, s = (1 + tanh(v / v_eps)) / 2: adds f = dc (s - 1/2) v.
* ``coulomb_friction``: f = Fc tanh(v / v_eps).
* ``progressive_spring``: cubic stiffening f = k3 d³.
* ``gas_spring``: the nonlinear part of a polytropic gas charge of preload F0 [N] and gas column L [m],
  compressed by -d: f = F0 (1 - (1 + d/L)^-kappa) - F0 kappa d / L. Its linear part F0 kappa / L is
  part of the configured spring kf/kr; what remains stiffens in compression and softens in rebound.
* ``hysteresis``: Bouc-Wen (n = 2) beside the spring, f = alpha z, with one state per corner
  zd = A v - beta v z² - gamma |v| z |z| (z [m] saturates at sqrt(A / (beta + gamma))).
* ``backlash``: play of width gap between strut and damper: the damper piston x_b (state per corner,
  centred at rest) is driven through contact faces of stiffness k_contact that close after a dead zone
  of gap/2 either way: transmitted force F = k_contact * deadzone(d - x_b), xd_b = F / c. It replaces
  the configured damper force c v (adds F - c v). gap = 0 is the rigid mount (the effect switched off).
* ``damper_lag``: the damper force F_d follows its input (c v, or the backlash force) through a
  first-order lag of time constant T (state per corner): dF_d/dt = (c v - F_d) / T; adds F_d - c v.
  T = 0 is no lag.

The tyre effect: ``tyre_damping``: f = ct (xd_i - yd_i), a damper beside each tyre spring.

Effects in parallel add; backlash and lag act in series on the configured damper (lag after backlash).
Force laws use ``error_model="numpy"``: an unstable or unphysical candidate (e.g. a gas spring bottoming
out) gives NaN or inf responses, not an exception.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numba
import numpy as np
from numpy.typing import ArrayLike, NDArray

N_CORNERS = 4
AXLES = ("f", "r")
AXLE_OF_CORNER = (0, 0, 1, 1)  # corners 1, 2 front; 3, 4 rear


@dataclass(frozen=True)
class Param:
    """One parameter of an effect; `per_axle` ones appear as <name>_f and <name>_r."""

    name: str
    default: float
    lower: float
    upper: float
    unit: str
    doc: str
    per_axle: bool = True
    open_lower: bool = False  # lower bound excluded (e.g. a smoothing velocity > 0)


@dataclass(frozen=True)
class Effect:
    """An effect of the library: its parameters, the one whose zero switches it off, states per corner."""

    name: str
    doc: str
    params: tuple[Param, ...]
    strength: str  # base name of the parameter that is zero when the effect is inactive
    states: int = 0  # internal states per corner
    tyre: bool = False  # acts on the tyres (needs the tyre struts)

    def names(self) -> tuple[str, ...]:
        """Parameter names as a config gives them (per-axle ones with _f / _r)."""
        out: list[str] = []
        for p in self.params:
            out.extend((f"{p.name}_f", f"{p.name}_r") if p.per_axle else (p.name,))
        return tuple(out)

    def param(self, name: str) -> Param:
        """The Param behind a config name (``alpha_f`` -> alpha)."""
        for p in self.params:
            if name == p.name and not p.per_axle:
                return p
            if p.per_axle and name in (f"{p.name}_f", f"{p.name}_r"):
                return p
        raise KeyError(name)

    def defaults(self) -> dict[str, float]:
        """Every parameter at its default (the strength at zero: inactive)."""
        return {n: self.param(n).default for n in self.names()}


LIBRARY: dict[str, Effect] = {
    e.name: e
    for e in (
        Effect(
            "asymmetric_damping",
            "rebound/compression damping c + dc/2 / c - dc/2 with the smooth switch of Fleps-Dezasse Eq. 4-5",
            (
                Param("dc", 0.0, -1e5, 1e5, "N s/m", "rebound minus compression damping (|dc| < 2 c)"),
                Param("v_eps", 0.02, 0.0, 10.0, "m/s", "width of the smooth switch", per_axle=False, open_lower=True),
            ),
            strength="dc",
        ),
        Effect(
            "coulomb_friction",
            "strut friction Fc tanh(v / v_eps)",
            (
                Param("Fc", 0.0, 0.0, 1e4, "N", "friction force level"),
                Param("v_eps", 0.01, 0.0, 10.0, "m/s", "tanh smoothing velocity", per_axle=False, open_lower=True),
            ),
            strength="Fc",
        ),
        Effect(
            "progressive_spring",
            "cubic stiffening k3 d^3 beside the linear spring",
            (Param("k3", 0.0, 0.0, 1e12, "N/m^3", "cubic stiffness"),),
            strength="k3",
        ),
        Effect(
            "tyre_damping",
            "a damper beside each tyre spring, on wheel minus road velocity",
            (Param("ct", 0.0, 0.0, 1e5, "N s/m", "tyre damping"),),
            strength="ct",
            tyre=True,
        ),
        Effect(
            "hysteresis",
            "Bouc-Wen (n = 2) in the strut, f = alpha z",
            (
                Param("alpha", 0.0, 0.0, 1e7, "N/m", "Bouc-Wen force per unit z"),
                Param("beta", 2e4, -1e12, 1e12, "1/m^2", "Bouc-Wen shape (beta + gamma > 0)", per_axle=False),
                Param("gamma", 2e4, -1e12, 1e12, "1/m^2", "Bouc-Wen shape", per_axle=False),
                Param("A", 1.0, 0.0, 100.0, "-", "Bouc-Wen initial slope dz/dd", per_axle=False),
            ),
            strength="alpha",
            states=1,
        ),
        Effect(
            "gas_spring",
            "nonlinear part of a polytropic gas charge: preload F0, gas column L, exponent kappa",
            (
                Param("F0", 0.0, 0.0, 1e6, "N", "gas preload at static equilibrium"),
                Param("L", 0.1, 0.0, 10.0, "m", "equivalent gas column length", per_axle=False, open_lower=True),
                Param("kappa", 1.4, 1.0, 2.0, "-", "polytropic exponent", per_axle=False),
            ),
            strength="F0",
        ),
        Effect(
            "backlash",
            "play of width gap before the damper engages, contact faces of stiffness k_contact",
            (
                Param("gap", 0.0, 0.0, 0.1, "m", "total play (dead zone gap/2 either way)"),
                Param("k_contact", 2e6, 0.0, 1e10, "N/m", "contact stiffness", per_axle=False, open_lower=True),
            ),
            strength="gap",
            states=1,
        ),
        Effect(
            "damper_lag",
            "the damper force follows c v through a first-order lag",
            (Param("T", 0.0, 0.0, 1.0, "s", "lag time constant"),),
            strength="T",
            states=1,
        ),
    )
}
EFFECT_NAMES = tuple(LIBRARY)


def _layout() -> dict[str, int]:
    """Slot of every entry of a params row: the linear damping c (4 corners), then per effect an 'on' flag,
    a state offset (stateful effects) and its parameters (4 corner slots for per-axle ones)."""
    slots: dict[str, int] = {}
    k = 0

    def add(key: str, width: int) -> None:
        nonlocal k
        slots[key] = k
        k += width

    add("c", N_CORNERS)
    for e in LIBRARY.values():
        add(f"{e.name}:on", 1)
        if e.states:
            add(f"{e.name}:z", 1)
        for p in e.params:
            add(f"{e.name}.{p.name}", N_CORNERS if p.per_axle else 1)
    slots[":width"] = k
    return slots


SLOTS = _layout()
N_PARAMS = SLOTS[":width"]

# Row slots as compile-time constants of the law.
_C = SLOTS["c"]
_AS_ON, _AS_DC = SLOTS["asymmetric_damping:on"], SLOTS["asymmetric_damping.dc"]
_AS_VE = SLOTS["asymmetric_damping.v_eps"]
_CF_ON, _CF_FC, _CF_VE = SLOTS["coulomb_friction:on"], SLOTS["coulomb_friction.Fc"], SLOTS["coulomb_friction.v_eps"]
_PS_ON, _PS_K3 = SLOTS["progressive_spring:on"], SLOTS["progressive_spring.k3"]
_TD_ON, _TD_CT = SLOTS["tyre_damping:on"], SLOTS["tyre_damping.ct"]
_HY_ON, _HY_Z, _HY_AL = SLOTS["hysteresis:on"], SLOTS["hysteresis:z"], SLOTS["hysteresis.alpha"]
_HY_BE, _HY_GA, _HY_A = SLOTS["hysteresis.beta"], SLOTS["hysteresis.gamma"], SLOTS["hysteresis.A"]
_GS_ON, _GS_F0, _GS_L, _GS_KA = (
    SLOTS["gas_spring:on"],
    SLOTS["gas_spring.F0"],
    SLOTS["gas_spring.L"],
    SLOTS["gas_spring.kappa"],
)
_BL_ON, _BL_Z, _BL_GAP, _BL_KC = (
    SLOTS["backlash:on"],
    SLOTS["backlash:z"],
    SLOTS["backlash.gap"],
    SLOTS["backlash.k_contact"],
)
_DL_ON, _DL_Z, _DL_T = SLOTS["damper_lag:on"], SLOTS["damper_lag:z"], SLOTS["damper_lag.T"]


@numba.njit(cache=True, error_model="numpy")
def strut_effects(d, dd, z, p, f_out, zd_out):  # pragma: no cover - compiled
    """Every effect present in the row p (see the module doc): struts 0..3 suspension, 4..7 tyres (if any)."""
    for i in range(N_CORNERS):
        x, v, c = d[i], dd[i], p[_C + i]
        f = 0.0
        if p[_AS_ON] != 0.0:
            f += 0.5 * p[_AS_DC + i] * math.tanh(v / p[_AS_VE]) * v
        if p[_CF_ON] != 0.0:
            f += p[_CF_FC + i] * math.tanh(v / p[_CF_VE])
        if p[_PS_ON] != 0.0:
            f += p[_PS_K3 + i] * x * x * x
        if p[_GS_ON] != 0.0:
            F0, L, kap = p[_GS_F0 + i], p[_GS_L], p[_GS_KA]
            if F0 != 0.0:
                f += F0 * (1.0 - (1.0 + x / L) ** (-kap)) - F0 * kap * x / L
        if p[_HY_ON] != 0.0:
            j = int(p[_HY_Z]) + i
            zz = z[j]
            f += p[_HY_AL + i] * zz
            zd_out[j] = p[_HY_A] * v - p[_HY_BE] * v * zz * zz - p[_HY_GA] * abs(v) * zz * abs(zz)
        damper = c * v  # the configured damper's force, then through backlash and lag
        if p[_BL_ON] != 0.0:
            j = int(p[_BL_Z]) + i
            half = 0.5 * p[_BL_GAP + i]
            if half > 0.0:
                r = x - z[j]
                pen = r - half if r > half else (r + half if r < -half else 0.0)
                damper = p[_BL_KC] * pen
                zd_out[j] = damper / c
            else:
                zd_out[j] = 0.0
        if p[_DL_ON] != 0.0:
            j = int(p[_DL_Z]) + i
            T = p[_DL_T + i]
            if T > 0.0:
                zd_out[j] = (damper - z[j]) / T
                damper = z[j]
            else:
                zd_out[j] = 0.0
        f_out[i] = f + damper - c * v
    for i in range(N_CORNERS, f_out.shape[0]):
        f_out[i] = p[_TD_CT + i - N_CORNERS] * dd[i] if p[_TD_ON] != 0.0 else 0.0


@dataclass(frozen=True)
class EffectSet:
    """The effects of one simulation: which are present, their parameters for a batch, the kernel's sizes."""

    rows: NDArray  # (P, N_PARAMS) params rows of strut_effects
    n_z: int  # internal states (all corners)
    tyres: bool  # the tyre struts are needed


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
    """Params rows (P = prod(batch)) for the present effects (values scalars or arrays of shape `batch`;
    missing parameters at their defaults) and the configured linear damping cf, cr [N s/m] of each car."""
    check_names(effects)
    P = int(np.prod(batch, dtype=int))

    def flat(value: ArrayLike) -> NDArray:
        return np.broadcast_to(np.asarray(value, dtype=float), batch).reshape(P)

    rows = np.zeros((P, N_PARAMS))
    c = (flat(cf), flat(cr))
    for i in range(N_CORNERS):
        rows[:, _C + i] = c[AXLE_OF_CORNER[i]]
    n_z = 0
    for name, given in effects.items():
        e = LIBRARY[name]
        values = {**e.defaults(), **given}
        rows[:, SLOTS[f"{name}:on"]] = 1.0
        if e.states:
            rows[:, SLOTS[f"{name}:z"]] = n_z
            n_z += e.states * N_CORNERS
        for p in e.params:
            s = SLOTS[f"{name}.{p.name}"]
            if p.per_axle:
                axle = (flat(values[f"{p.name}_f"]), flat(values[f"{p.name}_r"]))
                for i in range(N_CORNERS):
                    rows[:, s + i] = axle[AXLE_OF_CORNER[i]]
            else:
                rows[:, s] = flat(values[p.name])
    return EffectSet(rows=rows, n_z=n_z, tyres="tyre_damping" in effects)


def bound_violation(effect: str, name: str, value: float) -> str | None:
    """Why `value` is outside the physical bounds of effect.name, or None if it is inside."""
    p = LIBRARY[effect].param(name)
    low_ok = value > p.lower if p.open_lower else value >= p.lower
    if low_ok and value <= p.upper:
        return None
    lo = "(" if p.open_lower else "["
    return f"{effect}.{name} = {value:g} {p.unit} is outside its physical range {lo}{p.lower:g}, {p.upper:g}]"


# ------------------------------------------------------------------------------------------ the test bench

BENCH_EFFECTS = ("asymmetric_damping", "coulomb_friction", "progressive_spring", "hysteresis", "damper_lag")
"""Library effects that act on a damper on a test bench through ``bench_effects`` (the damper's own gas
force and backlash are its model's front end: k1, x0 and gap in models/damper.py)."""


@numba.njit(cache=True, error_model="numpy")
def bench_effects(d, dd, z, p, f_out, zd_out):  # pragma: no cover - compiled
    """The library's strut effects around a damper on a test bench (corner-1 slots of a params row).

    Channels d = [x, v, F_damper, F_gas]: the prescribed stroke x [m] and velocity v [m/s] (rebound
    positive), the declared damper model's force without its gas part [N], and its gas force [N].
    The damper force goes through ``damper_lag`` (dF/dt = (F_damper - F) / T) and the parallel effects
    add, with the formulas of ``strut_effects``: f_out[0] = F_gas + lag(F_damper) + effects.
    """
    x, v, damper = d[0], d[1], d[2]
    f = d[3]
    if p[_AS_ON] != 0.0:
        f += 0.5 * p[_AS_DC] * math.tanh(v / p[_AS_VE]) * v
    if p[_CF_ON] != 0.0:
        f += p[_CF_FC] * math.tanh(v / p[_CF_VE])
    if p[_PS_ON] != 0.0:
        f += p[_PS_K3] * x * x * x
    if p[_HY_ON] != 0.0:
        j = int(p[_HY_Z])
        zz = z[j]
        f += p[_HY_AL] * zz
        zd_out[j] = p[_HY_A] * v - p[_HY_BE] * v * zz * zz - p[_HY_GA] * abs(v) * zz * abs(zz)
    if p[_DL_ON] != 0.0:
        j = int(p[_DL_Z])
        T = p[_DL_T]
        if T > 0.0:
            zd_out[j] = (damper - z[j]) / T
            damper = z[j]
        else:
            zd_out[j] = 0.0
    f_out[0] = f + damper
    for i in range(1, f_out.shape[0]):
        f_out[i] = 0.0


def bench_effect_rows(effects: Mapping[str, Mapping[str, ArrayLike]], P: int) -> EffectSet:
    """Params rows of ``bench_effects`` for P candidates; effect parameters by their base names
    (``alpha``, not ``alpha_f``): one damper, so the per-axle pair carries the same value."""
    unknown = [e for e in effects if e not in BENCH_EFFECTS]
    if unknown:
        raise KeyError(f"not an effect on the test bench: {unknown} (bench effects: {', '.join(BENCH_EFFECTS)})")
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
    return effect_rows(per_axle, 0.0, 0.0, (P,))


def bench_lag_state(eset: EffectSet) -> int | None:
    """Index of the damper-lag state in a bench effect set's states (None without the lag)."""
    row = eset.rows[0]
    return int(row[SLOTS["damper_lag:z"]]) if row[SLOTS["damper_lag:on"]] != 0.0 else None
