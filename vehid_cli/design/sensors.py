"""Choosing the mounted sensors (`design.sensors`) for a given road, on the per-channel Fisher information.

Channels carry independent noise, so their information adds up: one task with every candidate mounted gives each
candidate's share once, and any subset's bound is the bound of the sum, without simulating the subset again.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from ..config import Config
from ..identify.crlb import bound_from_information, weighted_sensitivities
from ..identify.task import Task, build_task
from .criterion import criterion_value, penalised
from .plan import Plan, apply_plan

EXHAUSTIVE = 5000  # at most this many sensor subsets are tried one by one


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
        return penalised(criterion_value(bound_from_information(task.names, at, F), config.design))

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
