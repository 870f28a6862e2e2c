"""Plan the test that identifies the car best, before anyone drives: `vehid design`.

A test is a `Plan`: the speed, the bump heights under the four corners, the bump's shape and length, the record's
duration and (optionally) which of the candidate sensors are mounted. Its merit is the Cramér–Rao bound of the
configured identification on it, computed exactly as `vehid identify` computes it (`identification.build_task`
then `Task.bound()` on the config with the plan written in), reduced to one number by the criterion:

- `nre`: the bound on the per-run NRE RMS [%] (the root-sum-square of the per-parameter bounds);
- `d_optimal`: minus the log determinant of the Fisher information of the relative unknowns (maximised det);
- `worst` / `worst:<param>`: the largest per-parameter bound, or a named parameter's [%].

Heights. The responses are linear in the road, so scaling every height by c scales the sensitivities by c. With
an absolute noise floor (noise.sigma) the Fisher information scales by c²; under Eq. 15 (noise.level) sigma scales
by c too and the information is unchanged; a mix of both is F_Eq15 + c² F_floor, never worse for a larger c. So
the highest corner always sits at `design.heights.max` (under Eq. 15 any height gives the same bound), and the
design variables are the height ratios: `side` s in [-(1 - min/max), 1 - min/max] (s >= 0: side b1 at max, side b2
at (1 - s) max; s < 0 the other way round) and, with `per_axle`, `axle` (rear against front, the same way).

Search. Differential evolution (scipy, deferred updating, its generator spawned from `design.search.seed`) over the
designed variables (the shape as an integer variable), then coordinate sweeps over a grid through the optimum
until none improves it; the sweeps through the final optimum are the figures' curves. With `design.sensors` the
sensors are chosen for the current road (every subset when there are at most `EXHAUSTIVE` of them, else greedy
with exchanges, on the per-channel Fisher information, which adds up) and the road re-designed for them, until
the choice no longer changes. Candidates are evaluated in parallel over the executor's processes; every
evaluation is deterministic, so the result is bit-identical for any number of jobs.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..campaign.executor import Executor, LocalExecutor
from ..campaign.runner import run_campaign
from ..config import Config, config_from_dict
from ..config.design import Design
from ..core.errors import InputError
from ..identify.crlb import CramerRao, bound_from_information, weighted_sensitivities
from ..identify.task import Task, build_task
from ..models.sensors import FAMILY

PENALTY = 1e9  # the optimizer's value of a test that cannot identify every unknown (the criterion is infinite)
EXHAUSTIVE = 5000  # at most this many sensor subsets are tried one by one
MAX_ROUNDS = 3  # sensor choice / road design alternations
VARIABLES = ("speed_kmh", "side", "axle", "length", "duration", "shape")
LABELS = {
    "speed_kmh": "speed",
    "side": "left/right heights",
    "axle": "front/rear heights",
    "length": "bump length",
    "duration": "duration",
    "shape": "bump shape",
}
Progress = Callable[[str, int, "int | None"], None]


# ------------------------------------------------------------------------------------------ plans


@dataclass(frozen=True)
class Plan:
    """One test: speed [km/h], bump heights under corners 1..4 [m], shape, length [m], record duration [s], and
    the mounted sensors (names among design.sensors.candidates; None: the configured layout)."""

    speed_kmh: float
    heights: tuple[float, float, float, float]
    shape: str
    length: float
    duration: float
    sensors: tuple[str, ...] | None = None

    @property
    def side_ratio(self) -> float:
        """Height of side b2 over side b1 (front axle; corners 2 / 1)."""
        return self.heights[1] / self.heights[0] if self.heights[0] > 0 else math.inf

    def to_json(self) -> dict:
        return {
            "speed_kmh": self.speed_kmh, "heights": list(self.heights), "height_ratio_b2_b1": self.side_ratio,
            "shape": self.shape, "length": self.length, "duration": self.duration,
            "sensors": None if self.sensors is None else list(self.sensors),
        }  # fmt: skip


def configured_plan(config: Config) -> Plan:
    """The configured test as a plan."""
    bump = config.road.bump
    return Plan(
        speed_kmh=config.road.V * 3.6, heights=tuple(float(h) for h in bump.heights), shape=bump.shape,
        length=bump.length, duration=config.simulation.duration,
    )  # fmt: skip


def side_of(heights: Sequence[float]) -> float:
    """The side variable s of corner heights (front axle: corner 1 on side b1, corner 2 on side b2)."""
    h1, h2 = heights[0], heights[1]
    top = max(h1, h2)
    if top <= 0:
        return 0.0
    return 1.0 - h2 / h1 if h1 >= h2 else -(1.0 - h1 / h2)


def axle_of(heights: Sequence[float]) -> float:
    """The axle variable a of corner heights (side b1: corner 1 front, corner 4 rear)."""
    front, rear = heights[0], heights[3]
    if max(front, rear) <= 0:
        return 0.0
    return 1.0 - rear / front if front >= rear else -(1.0 - front / rear)


def corner_heights(top: float, side: float, axle: float, low: float = 0.0) -> tuple[float, float, float, float]:
    """Heights [m] of corners 1..4 with the highest at `top`, the side and axle ratios of s and a, none below `low`."""
    b1, b2 = (1.0, 1.0 - side) if side >= 0 else (1.0 + side, 1.0)
    front, rear = (1.0, 1.0 - axle) if axle >= 0 else (1.0 + axle, 1.0)
    h = top * np.array([b1 * front, b2 * front, b2 * rear, b1 * rear])
    return tuple(float(v) for v in np.maximum(h, low))


def apply_plan(config: Config, plan: Plan) -> Config:
    """The config with the plan's road, duration and sensors written in (validated; the source kept)."""
    raw = config.model_dump(mode="json", exclude_none=True, by_alias=True)
    road = raw["road"]
    road.pop("speed", None)
    road["speed_kmh"] = plan.speed_kmh
    road["bump"].update(shape=plan.shape, length=plan.length, heights=list(plan.heights))
    raw["simulation"]["duration"] = plan.duration
    if plan.sensors is not None:
        specs = {c.name: c for c in config.design.sensors.candidates}
        raw["layout"] = [specs[n].model_dump(mode="json", exclude_none=True) for n in plan.sensors]
    return config_from_dict(raw, source=config.source)


# ------------------------------------------------------------------------------------------ the space


@dataclass(frozen=True)
class Space:
    """The designed variables (VARIABLES with a range) and how a vector of them makes a plan from a base plan."""

    free: tuple[str, ...]
    lower: NDArray
    upper: NDArray
    shapes: tuple[str, ...]
    top: float | None  # the highest corner's height [m] (None: heights not designed)
    low: float  # no corner below this [m]

    def plan(self, x: NDArray, base: Plan) -> Plan:
        """The base plan with the free variables set to x (the shape variable is an index into `shapes`)."""
        v = dict(zip(self.free, np.asarray(x, dtype=float), strict=True))
        heights = base.heights
        if "side" in v or "axle" in v:
            top = self.top if self.top is not None else max(base.heights)
            side, axle = v.get("side", side_of(base.heights)), v.get("axle", axle_of(base.heights))
            heights = corner_heights(top, side, axle, self.low)
        shape = self.shapes[int(round(v["shape"]))] if "shape" in v else base.shape
        return dataclasses.replace(
            base, speed_kmh=float(v.get("speed_kmh", base.speed_kmh)), heights=heights, shape=shape,
            length=float(v.get("length", base.length)), duration=float(v.get("duration", base.duration)),
        )  # fmt: skip

    def vector(self, plan: Plan) -> NDArray:
        """The free variables of a plan."""
        known = {
            "speed_kmh": plan.speed_kmh, "side": side_of(plan.heights), "axle": axle_of(plan.heights),
            "length": plan.length, "duration": plan.duration,
            "shape": self.shapes.index(plan.shape) if plan.shape in self.shapes else 0,
        }  # fmt: skip
        return np.array([known[n] for n in self.free])


def design_space(design: Design) -> Space:
    """The variables the design section gives ranges to."""
    free, lower, upper = [], [], []

    def add(name: str, lo: float, hi: float) -> None:
        free.append(name)
        lower.append(lo)
        upper.append(hi)

    if design.speed_kmh is not None:
        add("speed_kmh", *design.speed_kmh)
    top, low = None, 0.0
    if design.heights is not None:
        top, low = design.heights.max, design.heights.min
        span = 1.0 - low / top
        add("side", -span, span)
        if design.heights.per_axle:
            add("axle", -span, span)
    if design.length is not None:
        add("length", *design.length)
    if design.duration is not None:
        add("duration", *design.duration)
    shapes = tuple(design.shapes or ())
    if len(shapes) > 1:
        add("shape", 0, len(shapes) - 1)
    return Space(tuple(free), np.array(lower, float), np.array(upper, float), shapes, top, low)


# ------------------------------------------------------------------------------------------ evaluating a plan


@dataclass(frozen=True)
class Evaluation:
    """A plan, its config and its bound; `criterion` is the value minimised (inf when some unknown is not
    identifiable), `log_det` the log determinant of the Fisher information of the relative unknowns."""

    plan: Plan
    config: Config
    bound: CramerRao
    criterion: float
    log_det: float


def log_det(bound: CramerRao) -> float:
    """log det of the Fisher information (-inf when singular)."""
    sign, value = np.linalg.slogdet(bound.fisher)
    return float(value) if sign > 0 else -math.inf


def criterion_value(bound: CramerRao, design: Design) -> float:
    """The criterion of a bound (smaller is better; inf when some unknown is not identifiable)."""
    if not np.all(bound.identifiable):
        return math.inf
    kind, name = design.criterion_kind, design.criterion_parameter
    if kind == "nre":
        return float(bound.nre_rms_percent)
    if kind == "d_optimal":
        return -log_det(bound)
    if name is None:
        return float(np.max(bound.re_sd_percent))
    return float(bound.re_sd_percent[bound.names.index(name)])


def bound_of(config: Config) -> CramerRao:
    """The bound `vehid identify` computes for a config (simulated data, at the truth)."""
    return build_task(config).bound()


def evaluate(config: Config, plan: Plan) -> Evaluation:
    """A plan's config and bound, exactly as `vehid identify` would compute them."""
    cfg = apply_plan(config, plan)
    bound = bound_of(cfg)
    return Evaluation(plan, cfg, bound, criterion_value(bound, config.design), log_det(bound))


@dataclass(frozen=True)
class Score:
    """What the search keeps of an evaluation (small, sent back from the workers)."""

    criterion: float
    nre: float
    re_sd: NDArray
    identifiable: NDArray


def _score_chunk(shared: tuple[Config, Space, Plan], chunk: tuple[int, NDArray]) -> tuple[int, list[Score]]:
    """Score a block of candidate vectors (the unit of parallel work)."""
    config, space, base = shared
    start, X = chunk
    out = []
    for x in X:
        bound = bound_of(apply_plan(config, space.plan(x, base)))
        out.append(Score(criterion_value(bound, config.design), bound.nre_rms_percent, bound.re_sd_percent,
                         bound.identifiable))  # fmt: skip
    return start, out


class Scorer:
    """Scores candidate vectors in parallel, in order, and counts the evaluations."""

    def __init__(self, config: Config, executor: Executor, jobs: int):
        self.config, self.executor, self.jobs, self.count = config, executor, jobs, 0

    def __call__(self, space: Space, base: Plan, X: NDArray) -> list[Score]:
        X = np.atleast_2d(np.asarray(X, dtype=float))
        n_chunks = max(1, min(len(X), 2 * self.jobs))
        edges = np.linspace(0, len(X), n_chunks + 1).astype(int)
        chunks = [(int(a), X[a:b]) for a, b in itertools.pairwise(edges) if b > a]
        results: dict[int, list[Score]] = {}
        for start, scores in self.executor.map_unordered(_score_chunk, (self.config, space, base), chunks):
            results[start] = scores
        self.count += len(X)
        return [s for start in sorted(results) for s in results[start]]


# ------------------------------------------------------------------------------------------ sensors


def channel_information(task: Task) -> dict[str, NDArray]:
    """Fisher information (D, D) of each channel of the task's objective, by sensor name: they add up to
    `task.information` (independent noise per channel; offsets profiled per channel)."""
    at = task.truth if task.truth is not None else task.nominal
    weighted = weighted_sensitivities(task.experiment, task.names, at, task.sigma, task.observed, task.offsets)
    out = {}
    for family, W in weighted.items():
        for c, name in enumerate(task.experiment.layout.names(family)):
            out[name] = W[:, c, :].T @ W[:, c, :]
    return out


def choose_sensors(config: Config, plan: Plan) -> tuple[str, ...]:
    """The best `design.sensors.count` candidates for the plan's road: every subset when there are at most
    EXHAUSTIVE, else greedy additions improved by single exchanges until none helps."""
    spec = config.design.sensors
    names = tuple(c.name for c in spec.candidates)
    task = build_task(apply_plan(config, dataclasses.replace(plan, sensors=names)))
    info = channel_information(task)
    at = task.truth if task.truth is not None else task.nominal
    # a candidate of a family the objective does not use carries no information (check_design refuses them)

    def value(subset: Sequence[str]) -> float:
        F = sum(info[n] for n in subset)
        return _penalised(criterion_value(bound_from_information(task.names, at, F), config.design))

    if math.comb(len(names), spec.count) <= EXHAUSTIVE:
        best = min(itertools.combinations(names, spec.count), key=value)
        return tuple(n for n in names if n in best)
    chosen: list[str] = []
    for _ in range(spec.count):  # greedy; an unidentifiable start is ranked by its summed information
        rest = [n for n in names if n not in chosen]
        chosen.append(min(rest, key=lambda n: (value(chosen + [n]), -np.trace(sum(info[m] for m in chosen + [n])))))
    improved = True
    while improved:
        improved = False
        current = value(chosen)
        for i, j in itertools.product(range(spec.count), range(len(names))):
            if names[j] in chosen:
                continue
            trial = chosen[:i] + [names[j]] + chosen[i + 1 :]
            if value(trial) < current - 1e-12 * abs(current):
                chosen, current, improved = trial, value(trial), True
    return tuple(n for n in names if n in chosen)


# ------------------------------------------------------------------------------------------ results


@dataclass(frozen=True)
class Sweep:
    """The criterion and the NRE bound along one variable, the others held at a plan; `values` in the variable's
    natural units (km/h, m, s; `side`: the lower side's height over the higher side's)."""

    variable: str
    through: str  # "designed" or "configured"
    x: NDArray  # the variable (the design vector's units)
    values: NDArray  # natural units, for the figure's axis
    criterion: NDArray
    nre: NDArray


@dataclass(frozen=True)
class Proposal:
    """A single-variable change of the configured test that makes every unknown identifiable."""

    variable: str
    value: float  # the new value (natural units: km/h, ratio, m, s; a shape's index into design.shapes)
    text: str  # e.g. "unequal left/right heights: ratio 0.9"
    change: float  # the change as a fraction of the variable's range (the cheapest is the smallest)
    nre_rms_percent: float  # the NRE bound of the changed test
    identifies: tuple[str, ...]  # the unknowns it makes identifiable


@dataclass(frozen=True)
class Verification:
    """Campaigns on both tests: the achieved per-run NRE RMS beside the bound."""

    runs: int
    configured_nre_rms: float
    configured_bound: float
    designed_nre_rms: float
    designed_bound: float

    @property
    def configured_ratio(self) -> float:
        return self.configured_nre_rms / self.configured_bound

    @property
    def designed_ratio(self) -> float:
        return self.designed_nre_rms / self.designed_bound

    @property
    def achieved_factor(self) -> float:
        """The achieved NRE's improvement (configured over designed)."""
        return self.configured_nre_rms / self.designed_nre_rms


@dataclass(frozen=True)
class DesignResult:
    """The configured test, the designed one, and what the search learned; ratios computed once here."""

    criterion: str
    configured: Evaluation
    designed: Evaluation
    space: Space
    unidentifiable: tuple[str, ...]  # unknowns the configured test cannot identify
    proposals: tuple[Proposal, ...]  # cheapest first
    sweeps: tuple[Sweep, ...]
    evaluations: int
    wall_s: float  # the design (search, sweeps, proposals), without --verify's campaigns [s]
    jobs: int
    noise_note: str
    verification: Verification | None = None
    improvement: float = dataclasses.field(init=False)  # the criterion's factor (configured over designed)
    nre_improvement: float = dataclasses.field(init=False)
    parameter_improvement: NDArray = dataclasses.field(init=False)

    def __post_init__(self) -> None:
        c, d = self.configured, self.designed
        if self.criterion.startswith("d_optimal"):  # the factor on the geometric mean of the bounds' sd
            D = len(d.bound.names)
            factor = math.exp((d.log_det - c.log_det) / (2 * D)) if math.isfinite(c.log_det) else math.inf
        else:
            factor = _ratio(c.criterion, d.criterion)
        object.__setattr__(self, "improvement", factor)
        object.__setattr__(self, "nre_improvement", _ratio(c.bound.nre_rms_percent, d.bound.nre_rms_percent))
        with np.errstate(divide="ignore", invalid="ignore"):
            per = np.asarray(c.bound.re_sd_percent) / np.asarray(d.bound.re_sd_percent)
        object.__setattr__(self, "parameter_improvement", per)


def _ratio(a: float, b: float) -> float:
    if b == 0 or not math.isfinite(b):
        return math.nan
    return a / b if math.isfinite(a) else math.inf


def _penalised(value: float) -> float:
    return value if math.isfinite(value) else PENALTY


# ------------------------------------------------------------------------------------------ checks


def check_design(config: Config) -> Design:
    """The design section against the rest of the config; InputError naming the key when it cannot be designed."""
    design = config.design
    src = config.source
    if design is None:
        raise InputError("no 'design' section: give the limits of the test to plan (see docs/design.md)", source=src,
                         key="design")  # fmt: skip
    if config.road.bump is None or config.road.file is not None:
        raise InputError("vehid design plans a bump test: configure road.bump (and no road.file)", source=src,
                         key="road.bump")  # fmt: skip
    name = design.criterion_parameter
    if name is not None and name not in config.identify.unknowns:
        raise InputError(
            f"'{name}' is not an unknown (identify.unknowns: {', '.join(config.identify.unknowns)})", source=src,
            key="design.criterion",
        )  # fmt: skip
    task = build_task(config)
    if task.noise_free:
        raise InputError("noise-free data has a zero bound for every test: set noise.level or noise.sigma",
                         source=src, key="noise.level")  # fmt: skip
    if design.sensors is not None:
        for i, c in enumerate(design.sensors.candidates):
            if FAMILY[c.kind] not in task.families:
                raise InputError(
                    f"a {c.kind} sensor is not used by the objective (families {', '.join(task.families)}; "
                    "see 'sensors' and identify.objective)", source=src, key=f"design.sensors.candidates.{i}.kind",
                )  # fmt: skip
    space = design_space(design)
    if not space.free and design.sensors is None:
        raise InputError("nothing to design: give a range (speed_kmh, heights, shapes, length, duration) or sensors",
                         source=src, key="design")  # fmt: skip
    base = configured_plan(config)
    names = tuple(c.name for c in design.sensors.candidates) if design.sensors else None
    for corner in (space.lower, space.upper):  # the test at the limits must be a valid config
        try:
            apply_plan(config, dataclasses.replace(space.plan(corner, base), sensors=names))
        except InputError as exc:
            raise InputError(f"the test at the limits is not valid: {exc.detail}", source=src,
                             key=f"design ({exc.key})" if exc.key else "design") from None  # fmt: skip
    return design


def noise_note(config: Config) -> str:
    """What the bump's height buys under the configured noise."""
    task = build_task(config)
    floors = [f for f in task.families if np.any(~np.isnan(task.experiment.noise_floors(f)))]
    if not floors:
        return (
            "noise: Eq. 15 (noise.level): sigma scales with each response's spread, so the absolute bump height buys "
            "nothing; the left/right (and front/rear) ratio, speed, shape, length and duration matter"
        )
    return (
        f"noise: absolute floors on {', '.join(floors)} (noise.sigma): a higher bump lowers the bound in proportion, "
        "so the highest corner is at design.heights.max"
    )


# ------------------------------------------------------------------------------------------ the search


def _differential_evolution(scorer: Scorer, space: Space, base: Plan, design: Design, progress: Progress) -> NDArray:
    """The best vector of the free variables by differential evolution (deferred updating, vectorised)."""
    from scipy.optimize import differential_evolution

    search = design.search
    n = len(space.free)
    (seq,) = np.random.SeedSequence(search.seed).spawn(1)
    generation = [0]

    def objective(XT: NDArray) -> NDArray:
        return np.array([_penalised(s.criterion) for s in scorer(space, base, XT.T)])

    def callback(*_args, **_kwargs) -> None:
        generation[0] += 1
        progress("search", generation[0], search.iterations)

    result = differential_evolution(
        objective, list(zip(space.lower, space.upper, strict=True)), maxiter=search.iterations,
        popsize=max(1, math.ceil(search.population / n)), rng=np.random.default_rng(seq), polish=False,
        updating="deferred", vectorized=True, callback=callback, x0=np.clip(space.vector(base), space.lower,
                                                                          space.upper),
        integrality=[name == "shape" for name in space.free],
    )  # fmt: skip
    return np.asarray(result.x, dtype=float)


def _grid(space: Space, name: str, points: int) -> NDArray:
    i = space.free.index(name)
    if name == "shape":
        return np.arange(len(space.shapes), dtype=float)
    return np.linspace(space.lower[i], space.upper[i], points)


def _sweep_vectors(space: Space, x: NDArray, name: str, points: int) -> tuple[NDArray, NDArray]:
    grid = _grid(space, name, points)
    X = np.repeat(x[None, :], grid.size, axis=0)
    X[:, space.free.index(name)] = grid
    return grid, X


def _polish(scorer: Scorer, space: Space, base: Plan, x: NDArray, best: float, points: int) -> tuple[NDArray, float]:
    """Coordinate sweeps over the grid through x until none improves the criterion (at most 3 passes)."""
    for _ in range(3):
        improved = False
        for name in space.free:
            grid, X = _sweep_vectors(space, x, name, points)
            scores = [_penalised(s.criterion) for s in scorer(space, base, X)]
            k = int(np.argmin(scores))
            if scores[k] < best - 1e-9 * abs(best):
                x, best, improved = X[k], scores[k], True
        if not improved:
            break
    return x, best


def natural(space: Space, name: str, x: NDArray) -> NDArray:
    """A variable in natural units: `side`/`axle` as the lower height over the higher one."""
    x = np.asarray(x, dtype=float)
    return 1.0 - np.abs(x) if name in ("side", "axle") else x


def _sweeps(scorer: Scorer, space: Space, plans: dict[str, Plan], points: int) -> list[Sweep]:
    """The criterion along speed and along the side ratio through each plan (figures); the side sweep keeps the
    higher side of the plan (ratio = lower over higher)."""
    out = []
    for name in ("speed_kmh", "side"):
        if name not in space.free:
            continue
        for through, plan in plans.items():
            x = space.vector(plan)
            grid, X = _sweep_vectors(space, x, name, points)
            if name == "side":  # one branch: the plan's higher side stays the higher
                sign = 1.0 if x[space.free.index("side")] >= 0 else -1.0
                grid = sign * np.linspace(0.0, space.upper[space.free.index("side")], points)
                X[:, space.free.index("side")] = grid
            scores = scorer(space, plan, X)
            out.append(Sweep(name, through, grid, natural(space, name, grid),
                             np.array([s.criterion for s in scores]), np.array([s.nre for s in scores])))  # fmt: skip
    return out


def _describe(name: str, value: float, space: Space) -> str:
    if name == "speed_kmh":
        return f"speed {value:.3g} km/h"
    if name == "side":
        return f"unequal left/right heights: ratio {value:.2g}"
    if name == "axle":
        return f"unequal front/rear heights: ratio {value:.2g}"
    if name == "length":
        return f"bump length {value:.3g} m"
    if name == "duration":
        return f"duration {value:.3g} s"
    return f"bump shape {space.shapes[int(value)]}"


def _proposals(scorer: Scorer, config: Config, space: Space, configured: Evaluation, points: int) -> list[Proposal]:
    """Single-variable changes of the configured test (each variable over its grid, the others as configured; the
    heights keep the configured highest corner) that make every unknown identifiable, cheapest (smallest change as
    a fraction of the variable's range) first, one per variable."""
    lost = [n for n, ok in zip(configured.bound.names, configured.bound.identifiable, strict=True) if not ok]
    if not lost or not space.free:
        return []
    local = dataclasses.replace(space, top=max(configured.plan.heights))
    x0 = local.vector(configured.plan)
    out = []
    for name in local.free:
        i = local.free.index(name)
        grid, X = _sweep_vectors(local, x0, name, 2 * points + 1)
        span = max(local.upper[i] - local.lower[i], 1e-300)
        changes = np.abs(grid - x0[i]) / span
        scores = scorer(local, configured.plan, X)
        ok = [k for k, s in enumerate(scores) if np.all(s.identifiable) and changes[k] > 0]
        if not ok:
            continue
        k = min(ok, key=lambda k: (changes[k], scores[k].nre))
        value = float(natural(local, name, grid[k])) if name != "shape" else float(grid[k])
        out.append(Proposal(name, value, _describe(name, value, local), float(changes[k]), scores[k].nre,
                            tuple(lost)))  # fmt: skip
    return sorted(out, key=lambda p: (p.change, p.nre_rms_percent))


def design_test(
    config: Config,
    *,
    jobs: int | None = None,
    executor: Executor | None = None,
    verify: int = 0,
    progress: Progress | None = None,
) -> DesignResult:
    """Plan the configured car's best test within config.design's limits; with `verify` > 0, run a campaign of that
    many runs on the configured and on the designed test (identify.* as configured)."""
    import contextlib

    design = check_design(config)
    progress = progress or (lambda *_: None)
    start = time.perf_counter()
    with contextlib.ExitStack() as stack:
        if executor is None:
            executor = stack.enter_context(LocalExecutor(jobs))
        n_jobs = getattr(executor, "jobs", 1)
        scorer = Scorer(config, executor, n_jobs)
        space = design_space(design)
        configured = evaluate(config, configured_plan(config))
        base = configured.plan
        chosen = None
        x = space.vector(base)
        for _ in range(MAX_ROUNDS):
            plan = space.plan(x, base) if space.free else base
            if design.sensors is not None:
                picked = choose_sensors(config, plan)
                if picked == chosen:
                    break
                chosen = picked
                base = dataclasses.replace(base, sensors=chosen)
            if space.free:
                x = _differential_evolution(scorer, space, base, design, progress)
                best = _penalised(scorer(space, base, x[None])[0].criterion)
                x, _ = _polish(scorer, space, base, x, best, design.search.grid)
            if design.sensors is None:
                break
        plan = space.plan(x, base) if space.free else base
        designed = evaluate(config, plan)
        progress("figures", 0, None)
        sweeps = _sweeps(scorer, space, {"designed": designed.plan, "configured": configured.plan}, design.search.grid)
        proposals = _proposals(scorer, config, space, configured, design.search.grid)
        wall_s = time.perf_counter() - start
        verification = None
        if verify > 0:
            verification = _verify(config, configured.config, designed.config, verify, executor, progress)
        evaluations = scorer.count + 2
    return DesignResult(
        criterion=design.criterion, configured=configured, designed=designed, space=space,
        unidentifiable=tuple(configured.bound.unidentifiable()), proposals=tuple(proposals), sweeps=tuple(sweeps),
        evaluations=evaluations, wall_s=wall_s, jobs=n_jobs, noise_note=noise_note(config),
        verification=verification,
    )  # fmt: skip


def _verify(config: Config, configured: Config, designed: Config, runs: int, executor: Executor,
            progress: Progress) -> Verification:  # fmt: skip
    """An N-run campaign on each test (the config's identify settings): per-run NRE RMS and the bound."""
    out = []
    for label, cfg in (("configured", configured), ("designed", designed)):
        raw = cfg.model_dump(mode="json", exclude_none=True, by_alias=True)
        raw["identify"]["runs"] = runs
        campaign = run_campaign(
            config_from_dict(raw, source=config.source), executor=executor,
            on_run=lambda done, total, label=label: progress(f"verify {label}", done, total),
        )  # fmt: skip
        out.append((campaign.summary.per_run_nre_rms, campaign.bound.nre_rms_percent))
    (cn, cb), (dn, db) = out
    return Verification(runs, float(cn), float(cb), float(dn), float(db))
