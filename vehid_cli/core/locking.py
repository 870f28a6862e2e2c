"""Exclusive locks on output files, so that concurrent vehid processes never write the same file at once.

A lock on `DIR/NAME` is an advisory `flock` on the hidden file `DIR/.NAME.lock`. The kernel drops it when its
holder exits, however it exits (SIGKILL included), so a crashed process never leaves a stale lock behind; the
holder removes the lock file when it is done. Because a waiter may have opened a lock file that its holder has
just removed, a lock counts as acquired only when the locked file is still the one at the path (the usual
inode check). POSIX only (Linux, macOS); on NFS, Linux implements `flock` with the NFS lock manager.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
from collections.abc import Iterator
from pathlib import Path

from .errors import InputError


class Busy(InputError):
    """Another process holds the lock (raised by a non-blocking `exclusive`)."""


def lock_path(path: str | Path) -> Path:
    """The lock file of `path`: `.NAME.lock` beside it."""
    path = Path(path)
    return path.with_name(f".{path.name}.lock")


def _acquire(path: Path, lock: Path, wait: bool) -> int:
    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        except BlockingIOError:
            os.close(fd)
            raise Busy(
                f"another vehid process is writing this file (it holds the lock {lock.name}); "
                "wait for it to finish or choose another output",
                source=str(path),
            ) from None
        except BaseException:
            os.close(fd)
            raise
        try:
            same = os.stat(lock).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode())
            return fd
        os.close(fd)  # its holder removed it while we waited: lock the new file


@contextlib.contextmanager
def exclusive(path: str | Path, *, wait: bool = False) -> Iterator[Path]:
    """Hold the lock of `path` for the block. Without `wait`, raise `Busy` at once if another process holds it;
    with `wait`, block until it is free. Yields the lock file's path."""
    lock = lock_path(path)
    fd = _acquire(Path(path), lock, wait)
    try:
        yield lock
    finally:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(lock)  # while still holding it: a waiter then finds the path gone and retries
        os.close(fd)
