"""The search for the best test within the `design:` limits: `design_test`, what `vehid design` calls.

It checks the section, scores the configured test, then designs: with `design.sensors` the sensors are chosen for
the current road (`sensors.py`) and the road re-designed for them (`optimum.py`), until the choice no longer changes
(at most MAX_ROUNDS); without, the road once. Then the profiles for the figures, the proposals when the configured
test cannot identify every unknown, and optionally the `--verify` campaigns. Candidates are scored in parallel over
the executor's processes; every evaluation is deterministic, so the result is bit-identical for any number of jobs.
"""

from __future__ import annotations

import contextlib
import dataclasses
import time

import numpy as np

from ..campaign.executor import Executor, LocalExecutor
from ..config import Config
from .checks import check_design, noise_note
from .criterion import evaluate, penalised
from .optimum import evolve, polish
from .plan import Plan, configured_plan
from .profiles import profiles_through
from .proposals import cheapest_changes
from .result import DesignResult
from .scoring import Progress, Scorer
from .sensors import choose_sensors
from .space import Space, design_space
from .verification import verification_campaigns

MAX_ROUNDS = 3  # sensor choice / road design alternations
MIRROR_TIE = 1e-6  # relative: mirror-image tests whose criteria differ by less are a tie (rounding, not physics)


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
        designed = evaluate(config, best_plan(scorer, config, space, configured.plan, progress))
        progress("figures", 0, None)
        profiles = profiles_through(scorer, space, {"designed": designed.plan, "configured": configured.plan},
                                    design.search.grid)  # fmt: skip
        proposals = cheapest_changes(scorer, config, space, configured, design.search.grid)
        wall_s = time.perf_counter() - start
        verification = None
        if verify > 0:
            verification = verification_campaigns(config, configured.config, designed.config, verify, executor,
                                                  progress)  # fmt: skip
        evaluations = scorer.count + 2
    return DesignResult(
        criterion=design.criterion, configured=configured, designed=designed, space=space,
        unidentifiable=tuple(configured.bound.unidentifiable()), proposals=tuple(proposals), sweeps=tuple(profiles),
        evaluations=evaluations, wall_s=wall_s, jobs=n_jobs, noise_note=noise_note(config),
        verification=verification,
    )  # fmt: skip


def best_plan(scorer: Scorer, config: Config, space: Space, base: Plan, progress: Progress) -> Plan:
    """The designed plan from the configured one: the road's variables by `evolve` and `polish`; with
    `design.sensors`, alternated with the sensors' choice for the current road until that choice stays."""
    design = config.design
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
            x = evolve(scorer, space, base, design, progress)
            best = penalised(scorer(space, base, x[None])[0].criterion)
            x, _ = polish(scorer, space, base, x, best, design.search.grid)
            x = prefer_side_b1(scorer, space, base, x)
        if design.sensors is None:
            break
    return space.plan(x, base) if space.free else base


def prefer_side_b1(scorer: Scorer, space: Space, base: Plan, x):
    """The tie-break between mirror-image tests: a car symmetric left/right gives the test with the sides' heights
    swapped the same bound (to rounding, which differs between machines and BLAS builds); of two such tests within
    MIRROR_TIE of each other the one with side b1 (corners 1 and 4, the left) at the higher bump is the design."""
    if "side" not in space.free:
        return x
    k = space.free.index("side")
    if x[k] >= 0:
        return x
    mirror = x.copy()
    mirror[k] = -x[k]
    here, there = (penalised(r.criterion) for r in scorer(space, base, np.stack([x, mirror])))
    return mirror if there <= here * (1 + MIRROR_TIE) else x
