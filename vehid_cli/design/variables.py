"""Designing a test through variables the system names in its config (`System.design_variables`: the rigs' chirp
band and amplitude, force amplitude, bump speed and height): each candidate is the config with the values written
at their keys, scored by the system's own Cramér–Rao bound (`build_system(cfg).bound()`, what `vehid identify`
reports) reduced by `design.criterion`; differential evolution then coordinate sweeps over a grid, as for the car.

Unknowns no test can separate (a free combination the system names, `System.unidentifiable`) stop the design with
that message (exit 2), as they stop identify: no choice of these variables fixes them.
"""

from __future__ import annotations

import itertools
import math
import time
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..campaign.executor import Executor
from ..config import AnyConfig, config_from_dict
from ..core.errors import InputError
from ..identify.crlb import CramerRao
from ..systems import build_system, system_class
from .criterion import criterion_value, penalised


@dataclass(frozen=True)
class VariableDesign:
    """The configured and the designed test: the variables' values, bounds and criteria."""

    criterion: str
    keys: tuple[str, ...]
    units: tuple[str, ...]
    lower: NDArray
    upper: NDArray
    configured_values: NDArray
    designed_values: NDArray
    configured: CramerRao
    designed: CramerRao
    configured_criterion: float
    designed_criterion: float
    designed_config: AnyConfig
    evaluations: int
    wall_s: float

    @property
    def improvement(self) -> float:
        """The criterion's factor, configured over designed (nan when not comparable)."""
        c, d = self.configured_criterion, self.designed_criterion
        if self.criterion.startswith("d_optimal") or d == 0 or not math.isfinite(d):
            return math.nan
        return c / d if math.isfinite(c) else math.inf


def _get(raw: dict, key: str) -> float:
    node = raw
    for part in key.split("."):
        node = node[part]
    return float(node)


def with_values(config: AnyConfig, variables, x: NDArray) -> AnyConfig:
    """The config with the variables' values x written at their keys (validated; the source kept)."""
    raw = config.model_dump(mode="json", exclude_none=True, by_alias=True)
    for v, value in zip(variables, x, strict=True):
        for key in v.replaces:
            head, _, last = key.rpartition(".")
            node = raw
            for part in head.split(".") if head else ():
                node = node.get(part, {})
            node.pop(last, None)
        *path, last = v.key.split(".")
        node = raw
        for part in path:
            node = node.setdefault(part, {})
        node[last] = float(value)
    return config_from_dict(raw, source=config.source)


def configured_values(config: AnyConfig, variables) -> NDArray:
    """The configured test's values of the variables (a key absent from the config: the range's middle)."""
    raw = config.model_dump(mode="json", exclude_none=True, by_alias=True)
    out = []
    for v in variables:
        try:
            out.append(_get(raw, v.key))
        except (KeyError, TypeError):
            out.append(0.5 * (v.lower + v.upper))
    return np.array(out)


def bound_at(config: AnyConfig, variables, x: NDArray) -> CramerRao:
    """The system's bound on the test x (simulated data, at the truth)."""
    return build_system(with_values(config, variables, x)).bound()


def _score_chunk(shared, chunk) -> tuple[int, list[float]]:
    config, variables = shared
    start, X = chunk
    return start, [criterion_value(bound_at(config, variables, x), config.design) for x in X]


class VariableScorer:
    """Candidate vectors scored in parallel over the executor, in order (bit-identical for any job count)."""

    def __init__(self, config: AnyConfig, variables, executor: Executor) -> None:
        self.config, self.variables, self.executor = config, variables, executor
        self.jobs, self.count = getattr(executor, "jobs", 1), 0

    def __call__(self, X: NDArray) -> NDArray:
        X = np.atleast_2d(np.asarray(X, dtype=float))
        edges = np.linspace(0, len(X), max(1, min(len(X), 2 * self.jobs)) + 1).astype(int)
        chunks = [(int(a), X[a:b]) for a, b in itertools.pairwise(edges) if b > a]
        results = dict(self.executor.map_unordered(_score_chunk, (self.config, self.variables), chunks))
        self.count += len(X)
        return np.array([s for start in sorted(results) for s in results[start]])


def refuse_free(config: AnyConfig, bound: CramerRao) -> None:
    """InputError (exit 2) naming the free combination of unknowns, when the system finds one in the bound."""
    system = build_system(config)
    message = system.unidentifiable(bound)
    if message is None:
        lost = bound.unidentifiable()
        message = f"no test within design: identifies {', '.join(lost)}" if lost else None
    if message is not None:
        raise InputError(f"vehid design: {message}", source=config.source, key="identify.unknowns")


def search(scorer: VariableScorer, lower: NDArray, upper: NDArray, x0: NDArray, design) -> NDArray:
    """Differential evolution (deferred updating, seeded), then coordinate sweeps over the grid until none improves."""
    from scipy.optimize import differential_evolution

    s = design.search
    (seq,) = np.random.SeedSequence(s.seed).spawn(1)
    result = differential_evolution(
        lambda XT: np.array([penalised(v) for v in scorer(XT.T)]), list(zip(lower, upper, strict=True)),
        maxiter=s.iterations, popsize=max(1, math.ceil(s.population / len(lower))), rng=np.random.default_rng(seq),
        polish=False, updating="deferred", vectorized=True, x0=np.clip(x0, lower, upper),
    )  # fmt: skip
    x, best = np.asarray(result.x, dtype=float), penalised(float(result.fun))
    for _ in range(3):
        improved = False
        for k in range(len(x)):
            X = np.repeat(x[None, :], s.grid, axis=0)
            X[:, k] = np.linspace(lower[k], upper[k], s.grid)
            scores = np.array([penalised(v) for v in scorer(X)])
            j = int(np.argmin(scores))
            if scores[j] < best - 1e-9 * abs(best):
                x, best, improved = X[j], float(scores[j]), True
        if not improved:
            break
    return x


def design_variables_test(config: AnyConfig, executor: Executor) -> VariableDesign:
    """The best test within config.design's ranges of the system's design variables."""
    start = time.perf_counter()
    variables = system_class(config).design_variables(config)
    design = config.design
    name = design.criterion_parameter
    if name is not None and name not in config.identify.unknowns:
        raise InputError(f"'{name}' is not an unknown (identify.unknowns: {', '.join(config.identify.unknowns)})",
                         source=config.source, key="design.criterion")  # fmt: skip
    lower = np.array([v.lower for v in variables])
    upper = np.array([v.upper for v in variables])
    x0 = configured_values(config, variables)
    configured = build_system(config).bound()
    if configured.nre_rms_percent == 0:
        raise InputError("noise-free data has a zero bound for every test: set noise.level or noise.sigma",
                         source=config.source, key="noise.level")  # fmt: skip
    if not np.all(configured.identifiable):  # a free combination no test of these variables separates
        probes = [lower, upper, 0.5 * (lower + upper)]
        if not any(np.all(bound_at(config, variables, p).identifiable) for p in probes):
            refuse_free(config, configured)
    scorer = VariableScorer(config, variables, executor)
    x = search(scorer, lower, upper, x0, design)
    designed_config = with_values(config, variables, x)
    designed = build_system(designed_config).bound()
    if not np.all(designed.identifiable):
        refuse_free(designed_config, designed)
    return VariableDesign(
        criterion=design.criterion, keys=tuple(v.key for v in variables), units=tuple(v.unit for v in variables),
        lower=lower, upper=upper, configured_values=x0, designed_values=x, configured=configured, designed=designed,
        configured_criterion=criterion_value(configured, design), designed_criterion=criterion_value(designed, design),
        designed_config=designed_config, evaluations=scorer.count + 2, wall_s=time.perf_counter() - start,
    )  # fmt: skip
