"""Executors: where the runs of a campaign execute. One identification run is the unit of work.

An executor applies `fn(shared, item)` to every item and yields the results as they finish, in any order.
For a campaign `fn` is `campaign.identify_run`, `shared` the identification task (config, reference data,
noise; built once, by the caller) and the items are run indices. A run's result depends only on the task and
its index (its random streams are spawned from the campaign seed), so an executor changes where a run
executes, never what it computes: results are bit-identical for every executor and any number of workers.

- `LocalExecutor(jobs)` (`--executor local`, the default): with one job, the runs execute in this process;
  otherwise in a pool of worker processes on this machine, kept for the executor's lifetime (a sweep's
  campaigns share it, so each worker imports and compiles once).
- `DaskExecutor(address)` (`--executor dask --scheduler tcp://HOST:PORT`): the runs execute on the workers
  of a Dask distributed cluster. The task is sent once per campaign to every worker (`scatter`); the workers
  must run the same vehid, NumPy, SciPy and numba versions as this process (checked when connecting and by
  every run), since their results would otherwise not be those of a local execution.

Every worker limits BLAS to one thread (our matrices are tiny and the parallelism is over runs). A local pool
worker ignores Ctrl-C (the parent stops the pool) and exits by itself if its parent is killed (SIGKILL).
"""

from __future__ import annotations

import contextlib
import os
import signal
import threading
import time
import uuid
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from typing import Any, TypeVar

from .. import __version__
from ..core.errors import InputError
from ..core.provenance import git_commit
from ..sim.kernel import set_threads
from .options import ADDRESS, check_executor_options

S = TypeVar("S")
T = TypeVar("T")
R = TypeVar("R")

CONNECT_TIMEOUT_S = float(os.environ.get("VEHID_DASK_TIMEOUT", "10"))  # reaching the scheduler [s]
WORKER_TIMEOUT_S = 60.0  # waiting for the cluster's first worker [s]
PARENT_POLL_S = 0.5  # how often a local pool worker checks that its parent is alive [s]


class Executor(ABC):
    """Runs units of work and yields their results as they finish. Use as a context manager: leaving the
    block normally releases the workers; leaving it by an exception (Ctrl-C, SIGTERM) stops them at once."""

    @property
    @abstractmethod
    def description(self) -> str:
        """Where the work runs, for messages and provenance (e.g. 'local, 2 processes')."""

    @abstractmethod
    def map_unordered(self, fn: Callable[[S, T], R], shared: S, items: Sequence[T]) -> Iterator[R]:
        """`fn(shared, item)` for every item, yielded as each finishes. Closing the iterator early (or an
        exception in the consumer) cancels the items not started yet."""

    def close(self, abort: bool = False) -> None:  # noqa: B027 - optional hook
        """Release the workers; `abort` stops work in progress instead of letting it finish."""

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(abort=exc_type is not None)


# ------------------------------------------------------------------------------------------ local


def _init_local_worker(parent: int) -> None:
    """Pool worker setup: one BLAS thread; Ctrl-C is the parent's to handle (it stops the workers), and
    SIGTERM ends a worker at once (a forked worker inherits the parent's handlers: undo them)."""
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
    set_threads(1)  # the pool's parallelism is over runs: one thread per batch
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    threading.Thread(target=_exit_with_parent, args=(parent,), daemon=True, name="vehid-parent-watch").start()


def _running(pid: int) -> bool:
    """Is process `pid` alive (a zombie counts as dead)?"""
    if os.path.isdir("/proc/self"):
        try:
            with open(f"/proc/{pid}/stat") as fh:
                return fh.read().rsplit(")", 1)[1].split()[0] not in ("Z", "X")
        except (FileNotFoundError, ProcessLookupError):
            return False
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    return True


def _exit_with_parent(parent: int) -> None:
    """A pool worker whose parent died (SIGKILL) would wait forever for work: the other workers hold the work
    queue open. Exit when the parent (the pid it was given, not whatever getppid() says by the time this
    runs) is gone: it is no longer our parent (fork, spawn) or no longer running (forkserver)."""
    direct = os.getppid() == parent
    while direct or _running(parent):
        if direct and os.getppid() != parent:
            break
        time.sleep(PARENT_POLL_S)
    os._exit(1)


@contextlib.contextmanager
def _silenced(thread: threading.Thread | None) -> Iterator[None]:
    """Drop uncaught exceptions of `thread` (only that thread's) while the context lasts."""
    previous = threading.excepthook

    def hook(args: threading.ExceptHookArgs) -> None:
        if thread is None or args.thread is not thread:
            previous(args)

    threading.excepthook = hook
    try:
        yield
    finally:
        threading.excepthook = previous


class LocalExecutor(Executor):
    """This machine: in-process for one job, else a pool of `jobs` worker processes (default: all cores)."""

    def __init__(self, jobs: int | None = None):
        if jobs is not None and jobs < 1:
            raise InputError(f"--jobs must be at least 1, got {jobs}")
        self.jobs = jobs or os.cpu_count() or 1
        self._pool: ProcessPoolExecutor | None = None

    @property
    def description(self) -> str:
        return f"local, {self.jobs} process{'es' if self.jobs > 1 else ''}"

    def map_unordered(self, fn: Callable[[S, T], R], shared: S, items: Sequence[T]) -> Iterator[R]:
        items = list(items)
        if self.jobs == 1 or len(items) <= 1:
            from threadpoolctl import threadpool_limits

            with threadpool_limits(1):  # the same BLAS threading as the pool's workers
                for item in items:
                    yield fn(shared, item)
            return
        if self._pool is None:
            self._pool = ProcessPoolExecutor(self.jobs, initializer=_init_local_worker, initargs=(os.getpid(),))
        pending = {self._pool.submit(fn, shared, item) for item in items}
        try:
            while pending:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                for future in done:
                    yield future.result()
        finally:
            for future in pending:
                future.cancel()

    def close(self, abort: bool = False) -> None:
        pool, self._pool = self._pool, None
        if pool is None:
            return
        if abort:
            # Runs in progress are redone on resume: stop them now rather than wait for them (a job scheduler's
            # SIGTERM leaves a short grace period). ProcessPoolExecutor has no public way to stop its workers.
            # The pool's manager thread then marks every pending future broken and, on CPython 3.11, raises for one
            # already cancelled (InvalidStateError, or KeyError in a race with its own clean-up): a traceback on
            # stderr from a pool we stopped on purpose. Silence that thread until the pool is shut down.
            # The queue that feeds the workers is not joined either: its feeder thread may be blocked writing to the
            # pipe of the workers just stopped (a full pipe no one reads), and the pool's shutdown joins it. CPython
            # 3.11.7 first closes that pipe's reading end (gh-94777), so the write fails; 3.11.2 (Debian 12's
            # python3) does not, and the shutdown then never returned.
            call_queue = getattr(pool, "_call_queue", None)
            if call_queue is not None:
                call_queue.cancel_join_thread()
            with _silenced(getattr(pool, "_executor_manager_thread", None)):
                for process in list(getattr(pool, "_processes", {}).values()):
                    process.terminate()
                pool.shutdown(wait=True, cancel_futures=True)
            return
        pool.shutdown(wait=True, cancel_futures=True)


# ------------------------------------------------------------------------------------------ dask


def code_identity() -> dict[str, str]:
    """What a run's numbers depend on besides its inputs: the vehid code and the numerical libraries."""
    from importlib import metadata

    out = {"vehid": __version__, "git_commit": git_commit()}
    for name in ("numpy", "scipy", "numba"):
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "absent"
    return out


def identity_mismatch(mine: dict[str, str], theirs: dict[str, str]) -> list[str]:
    """The entries in which two code identities differ (a git commit only counts when both are known)."""
    diffs = []
    for key, value in mine.items():
        other = theirs.get(key, "absent")
        if key == "git_commit" and "unknown" in (value, other):
            continue
        if other != value:
            diffs.append(f"{key} {other} (here {value})")
    return diffs


class IncompatibleWorker(RuntimeError):
    """A Dask worker runs other code than the client: its results would not be those of a local run."""


_WORKER_IDENTITY: dict[str, str] | None = None  # this worker process's code identity, computed once


def _on_dask_worker(fn: Callable[[Any, Any], Any], shared: Any, item: Any, identity: dict[str, str]) -> Any:
    """A unit of work on a Dask worker: check that the worker runs the client's code (any client may use the
    cluster) and, once per process, limit BLAS to one thread; then run it."""
    global _WORKER_IDENTITY
    if _WORKER_IDENTITY is None:
        from threadpoolctl import threadpool_limits

        threadpool_limits(1)
        set_threads(1)
        _WORKER_IDENTITY = code_identity()
    diffs = identity_mismatch(identity, _WORKER_IDENTITY)
    if diffs:
        raise IncompatibleWorker("; ".join(diffs))
    return fn(shared, item)


class DaskExecutor(Executor):
    """The workers of a Dask distributed cluster, reached through its scheduler (`tcp://HOST:PORT`)."""

    def __init__(self, address: str, connect_timeout: float = CONNECT_TIMEOUT_S):
        try:
            from distributed import Client
        except ImportError:
            raise InputError(
                "--executor dask needs the 'distributed' package: pip install 'dask[distributed]'"
            ) from None
        self.address = address
        if not ADDRESS.fullmatch(address):
            raise InputError(
                f"--scheduler expects an address tcp://HOST:PORT (as `dask scheduler` prints), got '{address}'"
            )
        try:
            self.client = Client(address, timeout=connect_timeout, set_as_default=False)
        except (OSError, TimeoutError, ValueError, TypeError) as exc:
            raise InputError(
                f"--scheduler {address}: cannot reach a Dask scheduler there within {connect_timeout:g} s "
                f"({exc.__class__.__name__}: {exc}); start one (`dask scheduler`) or check the address"
            ) from None
        try:
            self.client.wait_for_workers(1, timeout=WORKER_TIMEOUT_S)
        except (OSError, TimeoutError) as exc:
            self.client.close()
            raise InputError(
                f"--scheduler {address}: the scheduler has no workers after {WORKER_TIMEOUT_S:g} s ({exc}); "
                f"start some (`dask worker {address}`)"
            ) from None
        self.identity = code_identity()
        for worker, theirs in self.client.run(code_identity).items():
            diffs = identity_mismatch(self.identity, theirs)
            if diffs:
                self.client.close()
                raise InputError(
                    f"--scheduler {address}: worker {worker} runs other code than this process: {'; '.join(diffs)}; "
                    "install the same versions on the workers (their results would differ from a local run)"
                )

    @property
    def description(self) -> str:
        return f"dask, scheduler {self.address}"

    def map_unordered(self, fn: Callable[[S, T], R], shared: S, items: Sequence[T]) -> Iterator[R]:
        from distributed import as_completed

        items = list(items)
        if not items:
            return
        client, tag = self.client, uuid.uuid4().hex[:12]
        [shared_future] = client.scatter([shared], broadcast=True, hash=False)
        futures = [
            client.submit(_on_dask_worker, fn, shared_future, item, self.identity, pure=False, key=f"vehid-{tag}-{i}")
            for i, item in enumerate(items)
        ]
        try:
            for future in as_completed(futures, loop=client.loop):
                try:
                    result = future.result()
                except IncompatibleWorker as exc:
                    raise InputError(
                        f"--scheduler {self.address}: a worker runs other code than this process: {exc}; "
                        "install the same versions on the workers"
                    ) from None
                future.release()
                yield result
        finally:
            client.cancel([f for f in futures if not f.done()] + [shared_future])

    def close(self, abort: bool = False) -> None:
        self.client.close()


# ------------------------------------------------------------------------------------------ choosing


def make_executor(kind: str = "local", *, jobs: int | None = None, scheduler: str | None = None) -> Executor:
    """The executor the command-line options ask for (connecting to the Dask scheduler for `dask`)."""
    check_executor_options(kind, jobs=jobs, scheduler=scheduler)
    return LocalExecutor(jobs) if kind == "local" else DaskExecutor(str(scheduler))
