"""core/pools.py: the process's thread pools are made once and reused; a failed call drops the calls not started
and leaves none running; a forked child makes its own."""

from __future__ import annotations

import os
import threading
import time

import numpy as np
import pytest

from vehid_cli.core.pools import as_done, shared_pool
from vehid_cli.sim.kernel import in_parallel


def test_the_kernels_split_starts_its_threads_once():
    """Fifty batches split over two threads: at most two threads of the kernel's pool ever exist (a pool per call
    started a hundred)."""
    seen: set[str] = set()

    def rows(s: slice) -> None:
        seen.add(threading.current_thread().name)

    for _ in range(50):
        in_parallel(4, rows)  # from the main thread (pytest's): split when the process may use two cores
    kernel = [t for t in threading.enumerate() if t.name.startswith("vehid-kernel")]
    assert len(kernel) <= 2 and len(seen) <= 2
    assert shared_pool("kernel", 2) is shared_pool("kernel", 2) and shared_pool("x", 1) is not shared_pool("x", 2)


def test_a_failed_call_drops_the_calls_not_started_and_waits_for_the_running_one():
    pool = shared_pool("test-as-done", 1)
    started, finished = [], []

    def call(i: int) -> int:
        started.append(i)
        if i == 1:
            raise ValueError("call 1 fails")
        time.sleep(0.01)
        finished.append(i)
        return i

    got = []
    with pytest.raises(ValueError, match="call 1 fails"):
        for i, value in as_done(pool, call, range(20)):
            got.append((i, value))
    assert got == [(0, 0)] and len(started) <= 3  # one thread: the call it took before the cancel at most, no more
    assert set(finished) == set(started) - {1}  # and the running one was awaited: nothing runs behind the caller
    assert pool.submit(lambda: 7).result(timeout=5) == 7  # the pool still works


@pytest.mark.skipif(not hasattr(os, "fork"), reason="fork only")
def test_a_forked_child_makes_its_own_pool():
    assert shared_pool("kernel", 2).submit(lambda: 1).result() == 1  # the parent's pool has threads
    pid = os.fork()
    if pid == 0:  # the child: the parent's threads do not exist here; a new pool runs the work
        ok = shared_pool("kernel", 2).submit(lambda: np.ones(3).sum()).result(timeout=10) == 3.0
        os._exit(0 if ok else 1)
    _, status = os.waitpid(pid, 0)
    assert os.WEXITSTATUS(status) == 0
