"""Thread pools kept for the life of the process: the kernel's split of a batch over the cores and the diagnosis's
parallel candidate fits start their threads once, not at every call. A thread's start cost 1-2 ms, up to the
interpreter's 5 ms switch interval when another thread held the GIL: a 3 s diagnosis started 47 of them, 0.05-0.07 s
of its 2 s on the main thread's path."""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ThreadPoolExecutor, as_completed, wait
from typing import Any

_POOLS: dict[tuple[str, int], ThreadPoolExecutor] = {}
_LOCK = threading.Lock()


def shared_pool(name: str, workers: int) -> ThreadPoolExecutor:
    """The process's pool `name` of `workers` threads, made at its first use and reused after. A caller must not wait
    in one of its threads on work it submits to the same pool (the pool may have no thread left to run it)."""
    key = (name, workers)
    with _LOCK:
        pool = _POOLS.get(key)
        if pool is None:
            pool = _POOLS[key] = ThreadPoolExecutor(workers, thread_name_prefix=f"vehid-{name}")
        return pool


def as_done(pool: ThreadPoolExecutor, fn: Callable[[Any], Any], items: Sequence[Any]) -> Iterator[tuple[int, Any]]:
    """(i, fn(items[i])) for every item as its call finishes, the calls submitted to `pool` in the items' order. When
    one raises, or the caller stops (Ctrl-C), the calls not started are dropped and the running ones awaited: none is
    left running behind the caller's back."""
    futures = {pool.submit(fn, item): i for i, item in enumerate(items)}
    try:
        for future in as_completed(futures):
            yield futures[future], future.result()
    finally:
        for future in futures:
            future.cancel()
        wait(futures)


def _forget_pools() -> None:
    """In a forked child: the parent's pools have no threads there; new ones are made at first use."""
    global _LOCK
    _POOLS.clear()
    _LOCK = threading.Lock()


os.register_at_fork(after_in_child=_forget_pools)
