"""The parallel tests of a round's candidates (attribution.rank_candidates): one pool of threads for the known
parameters and the effects (the compiled kernels release the GIL), the parameters first, so that the decisions
their LRs settle (which screened effects cannot win, score.cannot_win; where an effect's fit stops, stops.py) are
made while the other fits run."""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor, as_completed
from typing import TypeVar

from ..sim.kernel import available_cores

C = TypeVar("C")
R = TypeVar("R")


def run_all(
    one: Callable[[C], R], candidates: list[C], key: Callable[[C], float], done: Callable[[int], None],
    first: Callable[[C], bool] = lambda _c: False, after_first: Callable[[list[R]], list[C]] | None = None,
) -> list[R]:  # fmt: skip
    """one(c) for every candidate, in parallel threads where there are cores; the results in the candidates' order,
    then those of the candidates after_first added. Those `first` says are submitted first, the others after them by
    `key` (smallest first: the longest fits, so that none runs alone at the end); once every first one is tested,
    after_first(their results, in order) is called in this thread (also when one of them failed, with the others'),
    and the candidates it returns are tested in the same threads. done(n) after each, in this thread. A test of the
    others may wait for what after_first decides: they start only once every first one has started (a pool's queue
    is in order), so every one they wait for is running."""
    after_first = after_first or (lambda _r: [])
    heads = [c for c in candidates if first(c)]
    tails = sorted((c for c in candidates if not first(c)), key=key)
    n = min(available_cores(), len(candidates))
    if n <= 1:
        got: dict[int, R] = {}
        for c in heads:
            got[id(c)] = one(c)
            done(len(got))
        more = after_first([got[id(c)] for c in heads])
        for c in tails + sorted(more, key=key):
            got[id(c)] = one(c)
            done(len(got))
        return [got[id(c)] for c in candidates + more]
    count = [0]

    def collect(futures: dict[Future, C], into: dict[int, R]) -> None:
        for future in as_completed(futures):
            into[id(futures[future])] = future.result()
            count[0] += 1
            done(count[0])

    got = {}
    with ThreadPoolExecutor(n) as pool:
        futures = {pool.submit(one, c): c for c in heads}
        rest = {pool.submit(one, c): c for c in tails}
        try:
            collect(futures, got)
        finally:
            more = after_first([got[id(c)] for c in heads if id(c) in got])
        rest.update({pool.submit(one, c): c for c in sorted(more, key=key)})
        collect(rest, got)
    return [got[id(c)] for c in candidates + more]
