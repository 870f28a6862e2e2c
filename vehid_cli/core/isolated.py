"""Run a file-parsing library in a forked child process, so that no file can take vehid down (issue 22).

Some readers of binary logger files are C code that trusts the bytes it is given: `scipy.io.loadmat` segfaults on
a damaged MAT v5 header, asammdf aborts the process (`malloc(): invalid size`) on an MDF4 file with ten flipped
bytes, and a size field inflated to 2**34 samples asks for 128 GiB. `in_child(fn, ...)` runs `fn` (the library's
part of a reader: open, parse, copy the arrays out) in a forked child and returns its result to the parent:

- the child's address space is limited (`MEMORY_BUDGET`, or a multiple of the file's size when larger): a
  declared size the file cannot hold becomes a MemoryError there, not a machine swapping or an OOM kill;
- its stdout and stderr go to /dev/null: a library's `Exception ignored in __del__` or glibc's abort message
  is not printed to the user;
- a crash (a signal), a hang (`timeout`) or any exception of the library becomes `Damaged`, which the reader
  turns into an InputError naming the file ("the file is damaged: the reader crashed (SIGSEGV)");
- an InputError raised by `fn` itself reaches the parent as it was raised.

Why fork, measured on this machine (issue 22): with the CLI imported (250 MB), fork + pickle of a small run costs
25 ms against 2 ms reading in process; a spawned interpreter would cost about 1 s of imports and break the 2 s
budget of `vehid check`. Checking every block of every format before the library reads it (the alternative) would
mean re-implementing the formats' parsers, and would still leave the library's own bugs. Where `os.fork` does not
exist (Windows), `fn` runs in this process, its exceptions still turned into `Damaged`.
"""

from __future__ import annotations

import faulthandler
import os
import pickle
import select
import signal
import time
import warnings
from collections.abc import Callable
from typing import TypeVar

from .errors import InputError, clip

T = TypeVar("T")
MEMORY_BUDGET = 4 << 30  # bytes of address space the child may add to what the parent has mapped
FILE_FACTOR = 64  # ... or this many times the file's size, when larger (a file read whole, and its arrays)
QUOTE = 200  # characters of a library's message quoted at most


class Damaged(Exception):
    """The library failed on the file: crashed, hung, ran out of its memory budget or raised."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


def describe(exc: BaseException, budget: int | None = None) -> str:
    """A library's exception in words: its type and (quoted) message."""
    message = clip(exc, QUOTE)
    if isinstance(exc, MemoryError):
        limit = f" of {budget / 2**30:.3g} GiB" if budget else ""
        return f"it declares more data than the reader's memory budget{limit} ({message or 'MemoryError'})"
    return f"{type(exc).__name__}: {message}" if message else type(exc).__name__


def in_child(fn: Callable[..., T], *args, size: int = 0, timeout: float | None = None) -> T:
    """`fn(*args)` run in a forked child; its result (picklable) back here. `size` is the file's size in bytes
    (the child's memory budget grows with it), `timeout` [s] the time it may take (default: 30 s plus 1 s per
    10 MB). Raises Damaged when the child crashes, hangs, or `fn` raises anything but an InputError."""
    if not hasattr(os, "fork"):
        try:
            return fn(*args)
        except InputError:
            raise
        except Exception as exc:  # noqa: BLE001 - the boundary of a parsing library: any failure is the file's
            raise Damaged(describe(exc)) from None
    timeout = 30.0 + size / 10e6 if timeout is None else timeout
    read_end, write_end = os.pipe()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # Python 3.12: fork of a process with threads
        pid = os.fork()
    if pid == 0:  # the child: never returns
        os.close(read_end)
        _child(fn, args, write_end, max(MEMORY_BUDGET, FILE_FACTOR * size))
    os.close(write_end)
    try:
        data = _receive(read_end, timeout)
    except BaseException:  # interrupted (Ctrl-C, an alarm): the child goes too
        _kill(pid)
        raise
    finally:
        os.close(read_end)
    if data is None:
        _kill(pid)
        raise Damaged(f"the reader did not finish within {timeout:.0f} s")
    status = _reap(pid)
    if not data:
        if os.WIFSIGNALED(status):
            sig = os.WTERMSIG(status)
            raise Damaged(f"the reader crashed ({_signal_name(sig)})")
        raise Damaged(f"the reader stopped without a result (exit status {os.waitstatus_to_exitcode(status)})")
    kind, payload = pickle.loads(data)
    if kind == "ok":
        return payload
    if kind == "input":
        detail, source, key = payload
        raise InputError(detail, source=source, key=key)
    raise Damaged(payload)


def _child(fn, args, write_end: int, budget: int) -> None:
    try:
        faulthandler.disable()  # a crash is the parent's to report (pytest and PYTHONFAULTHANDLER enable it)
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        _limit_memory(budget)
        try:
            result = ("ok", fn(*args))
        except InputError as exc:
            result = ("input", (exc.detail, exc.source, exc.key))
        except BaseException as exc:  # noqa: BLE001 - the boundary of a parsing library: any failure is the file's
            result = ("damaged", describe(exc, budget))
        try:
            data = pickle.dumps(result, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as exc:  # noqa: BLE001 - what the library returned cannot be carried back
            data = pickle.dumps(("damaged", f"its content cannot be carried back ({describe(exc)})"))
        with os.fdopen(write_end, "wb") as fh:
            fh.write(data)
    finally:
        os._exit(0)


def _limit_memory(budget: int) -> None:
    """Cap the child's address space at what it has mapped plus `budget` bytes (Linux; elsewhere unlimited)."""
    try:
        import resource

        with open("/proc/self/statm") as fh:
            mapped = int(fh.read().split()[0]) * os.sysconf("SC_PAGE_SIZE")
        soft, hard = resource.getrlimit(resource.RLIMIT_AS)
        limit = mapped + budget
        if hard != resource.RLIM_INFINITY:
            limit = min(limit, hard)
        if soft == resource.RLIM_INFINITY or soft > limit:
            resource.setrlimit(resource.RLIMIT_AS, (limit, hard))
    except (OSError, ValueError, ImportError):
        pass


def _receive(fd: int, timeout: float) -> bytes | None:
    """Everything the child writes, until it closes the pipe; None when that takes more than `timeout` s."""
    chunks, deadline = [], time.monotonic() + timeout
    while True:
        left = deadline - time.monotonic()
        ready, _, _ = select.select([fd], [], [], max(0.0, left))
        if not ready:
            return None
        chunk = os.read(fd, 1 << 20)
        if not chunk:
            return b"".join(chunks)
        chunks.append(chunk)


def _kill(pid: int) -> None:
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    _reap(pid)


def _reap(pid: int) -> int:
    while True:
        try:
            return os.waitpid(pid, 0)[1]
        except InterruptedError:
            continue
        except ChildProcessError:
            return 0


def _signal_name(sig: int) -> str:
    try:
        return f"{signal.Signals(sig).name}, signal {sig}"
    except ValueError:
        return f"signal {sig}"
