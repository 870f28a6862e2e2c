"""Exclusive locks on output files, so that concurrent vehid processes never write the same file at once.

A lock on `DIR/NAME` is an advisory `flock` on the hidden file `DIR/.NAME.lock`. The kernel drops it when its
holder exits, however it exits (SIGKILL included), so a crashed process never leaves a stale lock behind; the
holder removes the lock file when it is done. Because a waiter may have opened a lock file that its holder has
just removed, a lock counts as acquired only when the locked file is still the one at the path (the usual
inode check). POSIX only (Linux, macOS); on NFS, Linux implements `flock` with the NFS lock manager.

A lock file that cannot be made or written (a full disk, a read-only folder, a name too long, a directory, a FIFO
or a symlink in its place) is an error naming it (exit 2: `DiskFull`, `WriteFailed` or `InputError`), and a lock
file this process created is removed again: nothing is left behind. `holder` tells whether a live process holds the
lock of a path, without taking it (a running campaign from an interrupted one).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import stat
from collections.abc import Iterator
from pathlib import Path

from .errors import InputError
from .files import write_error


class Busy(InputError):
    """Another process holds the lock (raised by a non-blocking `exclusive`)."""


def lock_path(path: str | Path) -> Path:
    """The lock file of `path`: `.NAME.lock` beside it."""
    path = Path(path)
    return path.with_name(f".{path.name}.lock")


def _open_lock(path: Path, lock: Path) -> int:
    """The lock file's descriptor, created if missing; never through a symlink, never a non-regular file."""
    try:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK, 0o644)
    except OSError as exc:
        if exc.errno == errno.ELOOP:  # O_NOFOLLOW met a symlink
            raise InputError(
                f"its lock file {lock.name} is a symlink, not a lock vehid made; remove it", source=str(path)
            ) from None
        if exc.errno == errno.EISDIR:
            raise InputError(f"its lock file {lock.name} is a directory; remove it", source=str(path)) from None
        raise write_error(lock, exc) from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise InputError(f"its lock file {lock.name} is not a regular file; remove it", source=str(path))
    return fd


def _acquire(path: Path, lock: Path, wait: bool) -> int:
    while True:
        fd = _open_lock(path, lock)
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
            same = os.stat(lock, follow_symlinks=False).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        except BaseException:
            os.close(fd)
            raise
        if not same:
            os.close(fd)  # its holder removed it while we waited: lock the new file
            continue
        try:
            os.ftruncate(fd, 0)
            os.write(fd, f"{os.getpid()}\n".encode())
        except BaseException as exc:  # a full disk or a read-only folder: leave no lock file behind
            _release(lock, fd)
            if isinstance(exc, OSError):
                raise write_error(lock, exc) from None
            raise
        return fd


def _release(lock: Path, fd: int) -> None:
    """Remove the lock file (while still holding it: a waiter then finds the path gone and retries) and unlock."""
    try:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(lock)
    finally:
        os.close(fd)


def holder(path: str | Path) -> bool:
    """Whether a live process holds the lock of `path` now (without taking it, and without creating a lock file)."""
    lock = lock_path(path)
    try:
        fd = os.open(lock, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return False
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return False
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        return False
    except BlockingIOError:
        return True
    except OSError:
        return False
    finally:
        os.close(fd)


@contextlib.contextmanager
def exclusive(path: str | Path, *, wait: bool = False) -> Iterator[Path]:
    """Hold the lock of `path` for the block. Without `wait`, raise `Busy` at once if another process holds it;
    with `wait`, block until it is free. Yields the lock file's path."""
    lock = lock_path(path)
    fd = _acquire(Path(path), lock, wait)
    try:
        yield lock
    finally:
        _release(lock, fd)
