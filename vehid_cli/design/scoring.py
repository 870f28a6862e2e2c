"""Scoring candidate vectors of the design space in parallel over the executor's processes (`Scorer`), and the
`Progress` callback the search reports through.

Candidates are split into ordered blocks and put back in order; every evaluation is deterministic, so the scores,
and hence the design, are bit-identical for any number of jobs. Workers send back a small `Score`, not the bound.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..campaign.executor import Executor
from ..config import Config
from .criterion import bound_of, criterion_value
from .plan import Plan, apply_plan
from .space import Space

Progress = Callable[[str, int, "int | None"], None]  # (stage, done, total or None)


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

    def __init__(self, config: Config, executor: Executor, jobs: int) -> None:
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
