"""Run a file-parsing library in a child process of its own, so that no file can take vehid down (issue 22).

Some readers of binary logger files are C code that trusts the bytes it is given: `scipy.io.loadmat` segfaults on
a damaged MAT v5 header, asammdf aborts the process (`malloc(): invalid size`) on an MDF4 file with ten flipped
bytes, and a size field inflated to 2**34 samples asks for 128 GiB. `in_child(fn, ...)` runs `fn` (the library's
part of a reader: open, parse, copy the arrays out; a module-level function) in a child and returns its result:

- the child's address space is limited (`MEMORY_BUDGET`, or a multiple of the file's size when larger): a
  declared size the file cannot hold becomes a MemoryError there, not a machine swapping or an OOM kill;
- its stdout and stderr go to /dev/null: a library's `Exception ignored in __del__` or glibc's abort message
  is not printed to the user;
- a crash (a signal), a hang (`timeout`) or any exception of the library becomes `Damaged`, which the reader
  turns into an InputError naming the file ("the file is damaged: the reader crashed (SIGSEGV)");
- an InputError raised by `fn` itself reaches the parent as it was raised;
- the result comes back as its pickle and its arrays' buffers out of band (protocol 5, `_framed`), read into one
  block here: one copy of a record's arrays on either side, not three (pickle, chunks, joined bytes); a result cut
  short, or one that does not unpickle, is no result (`Damaged`).

The child is a fresh interpreter (`sys.executable`, this process's `sys.path`), not a fork: it imports only the
reader's module and its library (numpy, asammdf, ...). A fork would carry the whole of this process: with the CLI
imported, 150-250 MB of interpreter, scipy, numba and pydantic that the child's RSS counts a second time (issue 26:
the long record's reading peaked at parent + child = 2 x 150 MB + asammdf). The fresh interpreter costs about
0.2 s of start-up and imports (python, numpy, vehid_cli.io: 0.17 s and 30 MB measured), beside the 0.5 s that a
forked child also spent importing asammdf, which the parent never imports. Checking every block of every format
before the library reads it (the alternative to a child) would mean re-implementing the formats' parsers, and would
still leave the library's own bugs. Off POSIX, `fn` runs in this process, its exceptions still turned into `Damaged`.
"""

from __future__ import annotations

import faulthandler
import os
import pickle
import select
import signal
import struct
import subprocess
import sys
import time
from collections.abc import Callable
from typing import TypeVar

from .allocator import release_free_pages
from .errors import InputError, clip

T = TypeVar("T")
MEMORY_BUDGET = 4 << 30  # bytes of address space the child may add to what the parent has mapped
FILE_FACTOR = 64  # ... or this many times the file's size, when larger (a file read whole, and its arrays)
QUOTE = 200  # characters of a library's message quoted at most
ALIGN = 64  # [bytes] each out-of-band buffer of a result starts at a multiple of this in the block that holds them
IN_BAND = 4096  # [bytes] an array's buffer smaller than this is sent inside the pickle (its padding would cost more)
WAIT = 10.0  # [s] the parent waits this long for a child that sent no result to exit, then kills it


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
    """`fn(*args)` run in a child interpreter; its result (picklable) back here. `fn` and `args` are pickled (`fn`
    by reference: a module-level function), `size` is the file's size in bytes (the child's memory budget grows with
    it), `timeout` [s] the time it may take, start-up included (default: 30 s plus 1 s per 10 MB). Raises Damaged
    when the child crashes, hangs, or `fn` raises anything but an InputError."""
    if os.name != "posix":
        try:
            return fn(*args)
        except InputError:
            raise
        except Exception as exc:  # noqa: BLE001 - the boundary of a parsing library: any failure is the file's
            raise Damaged(describe(exc)) from None
    timeout = 30.0 + size / 10e6 if timeout is None else timeout
    budget = max(MEMORY_BUDGET, FILE_FACTOR * size)
    request = pickle.dumps(list(sys.path)) + pickle.dumps((fn, args, budget), protocol=pickle.HIGHEST_PROTOCOL)
    proc = subprocess.Popen(
        [sys.executable, "-c", _BOOT], stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL
    )
    try:
        try:
            proc.stdin.write(request)
            proc.stdin.close()
        except BrokenPipeError:  # the child died before reading its request: its status says how
            pass
        data = _receive(proc.stdout.fileno(), timeout, budget)
    except BaseException:  # interrupted (Ctrl-C, an alarm): the child goes too
        _kill(proc)
        raise
    finally:
        proc.stdout.close()
    if data is None:
        _kill(proc)
        raise Damaged(f"the reader did not finish within {timeout:.0f} s")
    try:
        status = proc.wait(WAIT if not data else None)
    except subprocess.TimeoutExpired:  # no result and still running: not a reader of ours
        _kill(proc)
        status = proc.returncode
    if not data:
        if status < 0:
            raise Damaged(f"the reader crashed ({_signal_name(-status)})")
        raise Damaged(f"the reader stopped without a result (exit status {status})")
    try:
        kind, payload = pickle.loads(data[0], buffers=data[1])
    except Exception as exc:  # noqa: BLE001 - bytes framed as a result that are not one
        raise Damaged(f"its result cannot be read ({describe(exc)})") from None
    if kind == "ok":
        return payload
    if kind == "input":
        detail, source, key = payload
        raise InputError(detail, source=source, key=key)
    raise Damaged(payload)


# The child's first lines: the parent's import path, then this module's `_serve` (its request follows on stdin).
_BOOT = f"import pickle, sys; sys.path[:] = pickle.load(sys.stdin.buffer); from {__name__} import _serve; _serve()"


def _serve() -> None:
    """In the child: read (fn, args, budget) from stdin, run fn(*args) within the memory budget with stdout and
    stderr at /dev/null, and write the pickled outcome to the stdout it was started with."""
    try:
        faulthandler.disable()  # a crash is the parent's to report (PYTHONFAULTHANDLER may enable it)
        out = os.dup(1)
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 1)
        os.dup2(devnull, 2)
        budget = MEMORY_BUDGET
        try:
            fn, args, budget = pickle.load(sys.stdin.buffer)
            _limit_memory(budget)
            result = ("ok", fn(*args))
        except InputError as exc:
            result = ("input", (exc.detail, exc.source, exc.key))
        except BaseException as exc:  # noqa: BLE001 - the boundary of a parsing library: any failure is the file's
            result = ("damaged", describe(exc, budget))
        release_free_pages()  # what the library freed (asammdf's working copies of a 60 s record: 16 MiB)
        try:
            parts = _framed(result)
        except Exception as exc:  # noqa: BLE001 - what the library returned cannot be carried back
            parts = _framed(("damaged", f"its content cannot be carried back ({describe(exc)})"))
        with os.fdopen(out, "wb") as fh:
            for part in parts:
                fh.write(part)
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


def _framed(result: object) -> list:
    """What the child writes for `result`: a header (the number of out-of-band buffers, the pickle's size, each
    buffer's size), the pickle (protocol 5) and the buffers of its arrays of IN_BAND bytes or more out of band, each
    padded to ALIGN bytes: written from the arrays' own memory, not copied into the pickle first."""
    buffers: list[pickle.PickleBuffer] = []

    def out_of_band(b: pickle.PickleBuffer) -> bool:  # False: out of band; a small array stays in the pickle
        if b.raw().nbytes < IN_BAND:
            return True
        buffers.append(b)
        return False

    data = pickle.dumps(result, protocol=5, buffer_callback=out_of_band)
    raws = [b.raw() for b in buffers]
    head = struct.pack(f"<{len(raws) + 2}Q", len(raws), len(data), *(r.nbytes for r in raws))
    parts: list = [head, data]
    for r in raws:
        parts += [r, bytes(_padded(r.nbytes) - r.nbytes)]
    return parts


def _padded(n: int) -> int:
    """n bytes rounded up to a multiple of ALIGN."""
    return -(-n // ALIGN) * ALIGN


def _receive(fd: int, timeout: float, most: int) -> tuple[bytearray, list[memoryview]] | tuple[()] | None:
    """What the child writes (`_framed`): the pickle and its buffers, the buffers read into one block of their padded
    sizes (views of it, each starting ALIGN-aligned within it): one copy of the result here, however many arrays it
    holds. () when the pipe closes before it is all there (the child died) or it declares more than `most` bytes (the
    child's memory budget, which it was made within), None when it takes more than `timeout` s."""
    deadline = time.monotonic() + timeout
    head = _read_into(fd, bytearray(16), deadline)
    if not head:
        return head if head is None else ()
    count, size = struct.unpack("<2Q", head)
    if 8 * count + size > most:
        return ()
    sizes = _read_into(fd, bytearray(8 * count), deadline)
    if sizes is None or len(sizes) < 8 * count:
        return sizes if sizes is None else ()
    lengths = struct.unpack(f"<{count}Q", sizes)
    offsets = [0]
    for n in lengths:
        offsets.append(offsets[-1] + _padded(n))
    if size + offsets[-1] > most or size == 0:
        return ()
    data = _read_into(fd, bytearray(size), deadline)
    if not data:
        return data if data is None else ()
    block = _read_into(fd, bytearray(offsets[-1]), deadline)
    if block is None or len(block) < offsets[-1]:
        return block if block is None else ()
    view = memoryview(block)
    return data, [view[a : a + n] for a, n in zip(offsets, lengths, strict=False)]


def _read_into(fd: int, buf: bytearray, deadline: float) -> bytearray | None:
    """`buf` filled from the pipe (an empty one at once); an empty bytearray when the pipe closes first, None past the
    `deadline`."""
    view, got = memoryview(buf), 0
    while got < len(buf):
        ready, _, _ = select.select([fd], [], [], max(0.0, deadline - time.monotonic()))
        if not ready:
            return None
        n = os.readv(fd, [view[got:]])
        if n == 0:
            return bytearray()
        got += n
    return buf


def _kill(proc: subprocess.Popen) -> None:
    proc.kill()
    proc.wait()


def _signal_name(sig: int) -> str:
    try:
        return f"{signal.Signals(sig).name}, signal {sig}"
    except ValueError:
        return f"signal {sig}"
