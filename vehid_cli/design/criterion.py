"""A plan's merit: the Cramér–Rao bound `vehid identify` computes for it (`identify.task.build_task` then
`Task.bound()` on the config with the plan written in), reduced to the one number the search minimises:

- `nre`: the bound on the per-run NRE RMS [%] (the root-sum-square of the per-parameter bounds);
- `d_optimal`: minus the log determinant of the Fisher information of the relative unknowns (maximised det);
- `worst` / `worst:<param>`: the largest per-parameter bound, or a named parameter's [%].

The bound is identify's own so that the designed test's merit is exactly what identify will report for it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config import Config
from ..config.design import Design
from ..identify.crlb import CramerRao
from ..identify.task import build_task
from .plan import Plan, apply_plan

PENALTY = 1e9  # the optimizer's value of a test that cannot identify every unknown (the criterion is infinite)


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


def penalised(value: float) -> float:
    """The criterion as the optimizers see it: PENALTY instead of infinity."""
    return value if math.isfinite(value) else PENALTY


def bound_of(config: Config) -> CramerRao:
    """The bound `vehid identify` computes for a config (simulated data, at the truth)."""
    return build_task(config).bound()


def evaluate(config: Config, plan: Plan) -> Evaluation:
    """A plan's config and bound, exactly as `vehid identify` would compute them."""
    cfg = apply_plan(config, plan)
    bound = bound_of(cfg)
    return Evaluation(plan, cfg, bound, criterion_value(bound, config.design), log_det(bound))
