"""What an effect of the library is: its parameters, its force (one compiled per-strut law), and how the closed loop
tries it (its candidate forms on the car and on a bench, and the shapes its force leaves in a residual).

An effect module defines one `Effect` and registers it (`models.effects.register`); the compiled laws of the car's
struts and of the bench are composed from the registered effects (`models.effects.law`: one generated function, the
effects' bodies in order, compiled once). The contract of the force, a plain function

    force(x, v, c, i, p, z, zd, f, damper) -> (f, damper)

for strut i (a corner 0..3, or 0 on a bench): deflection x [m] and its rate v [m/s], the configured linear damping
c [N s/m], the params row p, the states z and their rates zd (written), the parallel force f [N] summed so far and
the damper's force `damper` [N] so far (c v, or what a series effect made of it). `SLOT.<entry>` stands for the slot
of an entry of its params row: `SLOT.on`, `SLOT.z` (a stateful effect's first state), `SLOT.<param>` (a per-axle
parameter has four corner slots from there: `p[SLOT.dc + i]`). A parallel effect adds to f, a series effect (play,
lag) replaces `damper`; both start with ``if p[SLOT.on] != 0.0``, so an absent effect costs one branch and one whose
strength is zero adds exactly nothing; the body ends with ``return f, damper`` and uses numba-compilable Python
(math, numpy, builtins). A tyre effect's force acts on strut i of the tyres (x the tyre deflection, v its rate): it
adds to f, and `damper` is unused.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

from numpy.typing import NDArray


class _Slots:
    """`SLOT.<entry>` in an effect's force: replaced by the entry's slot when the composed law is generated."""

    def __getattr__(self, name: str) -> int:
        raise RuntimeError(f"SLOT.{name} is filled in by the composed law (models/effects/law.py), not at run time")


SLOT = _Slots()


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
class CandidateForm:
    """How the closed loop tries an effect (plain data; `diagnose.attribution.Candidate` is built from it).

    `unknowns` the names it adds (``effect.param``, or a damper's own parameters on a bench), their search `limits`
    and `start`; `strength` the unknowns whose interval must exclude their `null` value for a claim; `shape` the
    shape parameters (freed only where the data can tell them) with their `shape_limits`; `starts` values of the
    shape (or strength) parameters to start from; `linear`: the force is proportional to the strengths;
    `companions`: known parameters the effect replaces, freed with it once it is selected."""

    unknowns: tuple[str, ...]
    limits: dict[str, tuple[float, float]] = field(default_factory=dict)
    start: dict[str, float] = field(default_factory=dict)
    shape: tuple[str, ...] = ()
    shape_limits: dict[str, tuple[float, float]] = field(default_factory=dict)
    strength: tuple[str, ...] = ()
    null: dict[str, float] = field(default_factory=dict)
    starts: tuple[dict[str, float], ...] = ()
    linear: bool = True
    companions: tuple[str, ...] = ()


@dataclass(frozen=True)
class BenchScale:
    """The scales of a bench run a bench candidate's ranges are set from: the force, stroke and velocity standard
    deviations F [N], X [m], V [m/s], the sampling step dt [s], the Bouc-Wen loop widths [m] and the velocity scales
    [m/s] to start from, the stroke's mean [m]."""

    F: float
    X: float
    V: float
    dt: float
    yields: tuple[float, ...]
    velocities: tuple[float, ...]
    x_mean: float = 0.0  # the stroke's mean [m]


@dataclass(frozen=True)
class CarScale:
    """What a car (or rig) candidate's ranges are set from: the configured linear damping of the front and rear
    struts cf, cr [N s/m] and the RK4 step h [s] (the sampling step over the substeps; None on another integrator),
    which bounds how fast an internal state the fit may give an effect (the explicit step diverges beyond it)."""

    cf: float
    cr: float
    h: float | None = None


@dataclass(frozen=True)
class Shape:
    """A curve an additive strut force g(d) or h(v) can have, as the non-parametric estimate compares it: for the
    values x of its variable, candidate curves (curve, sign the amplitude must have (0: free), detail)."""

    name: str
    variable: str  # "deflection" or "velocity"
    curves: Callable[[NDArray], list[tuple[NDArray, int, str]]]
    rank: int  # its place among the shapes of its variable (ties go to the earlier)


@dataclass(frozen=True, eq=False)  # compared and hashed by identity: one object per registered effect
class Effect:
    """An effect of the library (see the module doc for the contract of `law`)."""

    name: str
    doc: str
    params: tuple[Param, ...]
    strength: str  # base name of the parameter that is zero when the effect is inactive
    force: Callable  # force(x, v, c, i, p, z, zd, f, damper) -> (f, damper), slots as SLOT.<entry> (module doc)
    order: int  # its place in the composed law: forces add (and series elements act) in this order
    states: int = 0  # internal states per strut
    tyre: bool = False  # acts on the tyres (needs the tyre struts)
    bench: bool = False  # acts around a damper on a test bench too (the composed bench law)
    car_candidate: Callable[[CarScale], CandidateForm] | None = None  # the car's damping and step -> its form there
    bench_candidate: Callable[[BenchScale], CandidateForm] | None = None  # a bench run's scales -> its form there
    shapes: tuple[Shape, ...] = ()  # the shapes its own force has
    resembles: Mapping[str, float] = field(default_factory=dict)  # shape name -> affinity: which shapes point to it

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


def per_axle_candidate(
    effect: str,
    param: str,
    low: Callable[[float], float],
    high: Callable[[float], float],
    s: CarScale,
    *,
    start: float | None = None,
    companions: tuple[str, ...] = (),
    shape_limits: Mapping[str, tuple[float, float]] | None = None,
    starts: tuple[dict[str, float], ...] = (),
    linear: bool = True,
) -> CandidateForm:
    """The car's usual candidate form: the strength `param` per axle (``effect.param_f``, ``_r``) in [low(c), high(c)]
    of the axle's configured damping c (`s`), null 0; shape parameters (``effect.name``) in `shape_limits`."""
    names = (f"{effect}.{param}_f", f"{effect}.{param}_r")
    limits = {n: (low(c), high(c)) for n, c in zip(names, (s.cf, s.cr), strict=True)}
    return CandidateForm(
        names, limits, {n: start for n in names} if start is not None else {}, tuple(shape_limits or {}),
        dict(shape_limits or {}), strength=names, null={n: 0.0 for n in names}, starts=tuple(starts), linear=linear,
        companions=tuple(companions),
    )  # fmt: skip


def constant(value: float) -> Callable[[float], float]:
    """A range end that does not depend on the configured damping."""
    return lambda _c: value


def velocity_starts(name: str, velocities: tuple[float, ...] = (0.003, 0.015, 0.06)) -> tuple[dict[str, float], ...]:
    """Starts of a smoothing or switch velocity ``effect.name`` [m/s] spread over a strut's range."""
    return tuple({name: s} for s in velocities)
