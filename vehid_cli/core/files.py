"""Files written so that a failure loses nothing: atomic replacement (temporary, fsync, rename), stale temporaries of
killed writers removed, a full disk reported as `DiskFull` and a refused write (read-only, no permission, a name too
long) as `WriteFailed`, each naming the file; output paths checked before any work; files of our own read only when
they are regular files of a sane size (a FIFO, a device or a huge file put in their place never hangs a read)."""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import re
import stat
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import NamedTuple

from .errors import DiskFull, InputError, WriteFailed


def read_text(path: str | Path, what: str, expected: str, encoding: str = "utf-8", limit: int | None = None) -> str:
    """A user's text file, or an InputError naming it: `what` it is ("config file") when missing or unreadable,
    `expected` ("a CSV file") when it is a directory, too large when it holds more than `limit` bytes."""
    source = str(path)
    try:
        with open(check_path_name(path, what), "rb") as fh:
            data = fh.read() if limit is None else fh.read(limit + 1)
        if limit is not None and len(data) > limit:
            raise InputError(f"{what} larger than {limit} bytes; expected {expected}", source=source)
        return data.decode(encoding).replace("\r\n", "\n").replace("\r", "\n")  # universal newlines, as open()
    except FileNotFoundError:
        raise InputError(f"{what} not found", source=source) from None
    except IsADirectoryError:
        raise InputError(f"is a directory, expected {expected}", source=source) from None
    except UnicodeDecodeError as exc:
        raise InputError(
            f"cannot read {what}: not {encoding} text (byte {exc.start}: {exc.reason}); expected {expected}",
            source=source,
        ) from None
    except OSError as exc:
        raise InputError(
            f"cannot read {what} ({exc.__class__.__name__}: {exc.strerror or exc})", source=source
        ) from None


OUTPUT_RESERVE = 20  # bytes an output's name leaves for the files made beside it (.NAME.XXXXXXXX.tmp, .NAME.lock)


def check_path_name(path: str | Path, what: str = "path", reserve: int = 0) -> Path:
    """`path`, or an InputError when the file system cannot take it as a name: a NUL byte, a name longer than the
    file system's limit (NAME_MAX, 255 bytes on most) less `reserve` bytes for the files named after it (an
    output's temporary and lock), a path longer than PATH_MAX."""
    text = os.fspath(path)
    if "\0" in text:
        raise InputError(f"the {what}'s name holds a NUL byte, which no file name may hold", source=repr(text))
    try:
        raw = os.fsencode(text)
    except UnicodeError:
        raise InputError(f"the {what}'s name cannot be encoded for the file system", source=repr(text)) from None
    parent = os.path.dirname(text) or "."
    name_max, path_max = _limits(parent)
    parts = raw.split(b"/")
    for i, part in enumerate(parts):
        room = name_max - (reserve if i == len(parts) - 1 else 0)
        if len(part) > room:
            spare = (
                f" ({name_max} per name, less {reserve} for vehid's temporary and lock files)"
                if room < name_max
                else ""
            )
            raise InputError(f"a name of {len(part)} bytes in the {what}; at most {room} bytes{spare}", source=text)
    if len(raw) >= path_max:
        raise InputError(
            f"a path of {len(raw)} bytes; the file system takes at most {path_max - 1} for the {what}", source=text
        )
    return Path(path)


def _limits(directory: str) -> tuple[int, int]:
    """NAME_MAX and PATH_MAX where `directory` (or its nearest existing ancestor) lives; 255 and 4096 if unknown."""
    probe = directory
    while probe and not os.path.isdir(probe) and os.path.dirname(probe) != probe:
        probe = os.path.dirname(probe)
    try:
        return os.pathconf(probe or ".", "PC_NAME_MAX"), os.pathconf(probe or ".", "PC_PATH_MAX")
    except (OSError, ValueError):
        return 255, 4096


def check_writable(path: str | Path, suffixes: Sequence[str]) -> Path:
    """Check an output path has a known suffix and a writable directory, before any work is done."""
    path = check_path_name(path, "output", OUTPUT_RESERVE)
    if path.suffix.lower() not in suffixes:
        raise InputError(
            f"unknown output type '{path.suffix}'; expected one of {', '.join(suffixes)}", source=str(path)
        )
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        state = "is a file, not a directory" if parent.exists() else "does not exist"
        raise InputError(f"output directory '{parent}' {state}", source=str(path))
    if path.is_dir():
        raise InputError("is a directory, expected a file name", source=str(path))
    if not os.access(parent, os.W_OK):
        raise InputError(f"output directory '{parent}' is not writable", source=str(path))
    return path


def check_writable_dir(path: str | Path, option: str | None = None) -> Path:
    """Check an output directory can be made and written (a probe file in it, or in its nearest existing
    ancestor: nothing is left behind), before any work. InputError names the option and the path."""
    path = check_path_name(path, "output directory", OUTPUT_RESERVE)
    source = f"{option} {path}" if option else str(path)
    if path.exists() and not path.is_dir():
        raise InputError("is a file, expected a directory", source=source)
    existing = path
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise InputError(f"cannot create the directory: '{existing}' is a file, not a directory", source=source)
    try:
        fd, probe = tempfile.mkstemp(prefix=".vehid-probe-", dir=existing)
    except OSError as exc:
        where = "the directory" if existing == path else f"'{existing}' (to create the directory in)"
        raise InputError(f"cannot write in {where}: {exc.strerror}", source=source) from None
    os.close(fd)
    os.unlink(probe)
    return path


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _fsync(path: Path, directory: bool = False) -> None:
    """Flush a file's (or a directory entry's) data to the disk."""
    fd = os.open(path, os.O_RDONLY | (getattr(os, "O_DIRECTORY", 0) if directory else 0))
    try:
        os.fsync(fd)
    except OSError:  # some file systems cannot fsync a directory: the rename is then as durable as they allow
        if not directory:
            raise
    finally:
        os.close(fd)


FULL_DISK = tuple(e for e in (errno.ENOSPC, getattr(errno, "EDQUOT", None)) if e is not None)
REFUSED = (
    errno.EROFS,
    errno.EACCES,
    errno.EPERM,
    errno.ENAMETOOLONG,
    errno.EISDIR,
    errno.ENOTDIR,
    errno.ELOOP,
    errno.EFBIG,
    errno.ENOENT,
    errno.EMLINK,
    errno.EEXIST,
    errno.EXDEV,
    errno.ETXTBSY,
    errno.EINVAL,
)  # fmt: skip - a write the system refuses for a reason a user can fix (exit 2), unlike an I/O error of the disk


def write_error(path: str | Path, exc: OSError) -> OSError:
    """The error to raise for `exc` met writing `path`: `DiskFull` or `WriteFailed` naming it, else `exc` itself."""
    if isinstance(exc, WriteFailed):
        return exc
    if exc.errno in FULL_DISK:
        return DiskFull(path, exc.errno)
    if exc.errno in REFUSED:
        return WriteFailed(path, exc.errno, exc.strerror or os.strerror(exc.errno))
    return exc


class FileIdentity(NamedTuple):
    """What tells, without reading it, that a file is the one read before, unchanged: its absolute path, device,
    inode, size [bytes], and modification and change times [ns]."""

    path: str
    device: int
    inode: int
    size: int
    modified_ns: int
    changed_ns: int


def file_identity(path: str | Path) -> FileIdentity:
    """The file's `FileIdentity` (one os.stat; its OSError, or ValueError for a name with a NUL byte, passes)."""
    info = os.stat(path)
    return FileIdentity(
        os.path.abspath(path), info.st_dev, info.st_ino, info.st_size, info.st_mtime_ns, info.st_ctime_ns
    )


def read_regular(path: str | Path, limit: int, what: str) -> bytes:
    """The bytes of `path` if it is a regular file (symlinks followed) of at most `limit` bytes; InputError naming it
    otherwise (a directory, a FIFO or a device in its place, a symlink loop, unreadable, larger than `limit`).
    FileNotFoundError passes through."""
    source = str(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)  # a FIFO opens at once instead of waiting for a writer
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise InputError(f"cannot read the {what} ({exc.strerror})", source=source) from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            kind = "a directory" if stat.S_ISDIR(info.st_mode) else "not a regular file"
            raise InputError(f"cannot read the {what}: it is {kind}", source=source)
        if info.st_size > limit:
            raise InputError(f"{what} is {info.st_size} bytes, more than the {limit} bytes one can hold", source=source)
        chunks, size = [], 0
        while chunk := os.read(fd, 1 << 20):
            chunks.append(chunk)
            size += len(chunk)
            if size > limit:
                raise InputError(f"{what} grew past {limit} bytes while it was read", source=source)
        return b"".join(chunks)
    except OSError as exc:
        raise InputError(f"cannot read the {what} ({exc.strerror})", source=source) from None
    finally:
        os.close(fd)


def _temporary_name(path: Path) -> re.Pattern:
    """Our temporaries of `path`: `.NAME.XXXXXXXX.tmp` as `tempfile.mkstemp` names them (no dot inside XXX, so
    `.NAME.bak.XXXXXXXX.tmp`, a temporary of NAME.bak, is not one of NAME's)."""
    return re.compile(rf"\.{re.escape(path.name)}\.[A-Za-z0-9_]+\.tmp")


def remove_stale_temporaries(path: str | Path) -> list[Path]:
    """Delete the unfinished atomic writes of `path` a killed process left (`.NAME.*.tmp` beside it); return them.

    A live writer holds an `flock` on its temporary (`atomic_path`), so only abandoned ones are removed, and only
    files of our own naming."""
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    pattern, removed = _temporary_name(path), []
    try:
        candidates = [p for p in parent.iterdir() if pattern.fullmatch(p.name)]
    except OSError:  # a missing or unreadable directory: nothing of ours to clean (the write reports it)
        return removed
    for tmp in candidates:
        try:
            fd = os.open(tmp, os.O_RDONLY | os.O_NONBLOCK | os.O_NOFOLLOW)  # a symlink or a FIFO is not ours
        except OSError:
            continue
        try:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                continue
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            os.unlink(tmp)  # while holding its lock: a writer that created it meanwhile sees it gone and retries
            removed.append(tmp)
        except OSError:  # BlockingIOError: a live writer's; FileNotFoundError: already gone
            pass
        finally:
            os.close(fd)
    return removed


def _locked_temporary(path: Path) -> tuple[int, Path]:
    """A new temporary beside `path`, locked (see `remove_stale_temporaries`): its descriptor and path."""
    while True:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent if str(path.parent) else ".")
        fcntl.flock(fd, fcntl.LOCK_EX)
        try:
            if os.stat(tmp).st_ino == os.fstat(fd).st_ino:
                return fd, Path(tmp)
        except FileNotFoundError:
            pass
        os.close(fd)  # a cleaner took it for a stale one before we locked it: make another


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside `path`; on success rename it into place, on failure remove it.

    The temporary file is flushed to the disk before the rename and the directory after it, so after a crash
    (or a power cut) `path` holds either its old content or the whole new one, never a part of it. Stale
    temporaries of `path` are removed first; a full disk (or quota) is `DiskFull` naming `path`, a write the system
    refuses (read-only, no permission, ...) `WriteFailed`."""
    path = Path(path)
    remove_stale_temporaries(path)
    fd = -1
    try:
        fd, tmp_path = _locked_temporary(path)
        try:
            os.chmod(tmp_path, 0o666 & ~_umask())  # mkstemp makes it private; results get the usual permissions
            yield tmp_path
            _fsync(tmp_path)
            os.replace(tmp_path, path)
        except BaseException:
            with contextlib.suppress(FileNotFoundError):
                tmp_path.unlink()
            raise
    except OSError as exc:
        error = write_error(path, exc)
        if error is exc:
            raise
        raise error from exc
    finally:
        if fd >= 0:
            os.close(fd)
    _fsync(tmp_path.parent, directory=True)


def _write_bytes(fh, data: bytes) -> None:
    """The one write of `write_bytes` (a test replaces it to fill the disk)."""
    fh.write(data)


def write_bytes(path: str | Path, data: bytes) -> None:
    """Write `data` to `path` atomically (`atomic_path`, fsynced): the old content or the whole new one."""
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        _write_bytes(fh, data)
