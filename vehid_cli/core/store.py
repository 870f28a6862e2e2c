"""The HDF5 store: vehid's HDF5 files built in memory and written with ordinary, atomic file I/O, with a checksum.

HDF5 reports a failed write (a full disk) from inside the library, sometimes only while it closes the file in a
destructor, where h5py can neither raise it nor clean up: warnings "Exception ignored", then a crash. So every
vehid HDF5 file is built with the in-memory core driver, and its bytes are written by `files.write_bytes`, where a
full disk is a Python `OSError` (`errors.DiskFull` naming the file).

A results file (a campaign) begins with a 512-byte HDF5 user block (which HDF5 skips) that holds the SHA-256 of
every byte after it. Every read checks it before HDF5 parses anything (`open_results`), so a file damaged after it
was written (truncated, partly copied, a disk error, an edit) is reported naming the file, never used, and never
handed to the HDF5 library, whose reactions to damaged metadata range over a dozen exception types. The file stays
ordinary HDF5 for every other tool. A checksum proves the bytes are the ones written, not that vehid wrote them (it
can be recomputed after an edit), so the file is then parsed in a child process (`h5snapshot`: a loop or a crash
of HDF5 on crafted metadata is an error naming the file) and its readers validate what they find. `save` and
`load` carry any `core.result.Result` through it.
"""

from __future__ import annotations

import contextlib
import hashlib
import itertools
import os
import stat
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path

import h5py

from .errors import InputError, quote
from .files import FileIdentity, file_identity, write_bytes
from .h5snapshot import Tree, read_tree
from .provenance import provenance
from .result import Result

_names = itertools.count()


@contextlib.contextmanager
def h5_file(
    path: str | Path, *, userblock: int = 0, head: Callable[[bytes], bytes] | None = None
) -> Iterator[h5py.File]:
    """A new, empty HDF5 file in memory; on a clean exit its bytes go to `path` atomically (nothing on an error).

    `userblock` reserves that many bytes at the start (HDF5 skips them); `head(body)` fills them from the bytes
    after them (e.g. a checksum), else they are zeros."""
    # The name only tells HDF5's open files apart: no file of that name is read or written (backing_store=False).
    name = f"vehid-memory-{next(_names)}-{Path(path).name}"
    h5 = h5py.File(name, "w", driver="core", backing_store=False, userblock_size=userblock or None)
    try:
        yield h5
        h5.flush()
        body = h5.id.get_file_image()  # everything after the user block
    finally:
        h5.close()
    block = head(body) if head is not None else bytes(userblock)
    if len(block) != userblock:
        raise ValueError(f"the user block must be {userblock} bytes, got {len(block)}")
    write_bytes(path, block + body)


USERBLOCK = 512  # bytes at the start of a campaign file that HDF5 skips: our checksum lives there


STAMP = b"vehid sha256 "  # then 64 hex digits of SHA-256(file[USERBLOCK:]) and a newline


HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def checksum_block(body: bytes) -> bytes:
    """The user block of a campaign file whose bytes after it are `body`: STAMP, SHA-256(body) in hex, newline,
    zeros up to USERBLOCK bytes."""
    return (STAMP + hashlib.sha256(body).hexdigest().encode() + b"\n").ljust(USERBLOCK, b"\0")


def stamp_checksum(path: str | Path) -> str:
    """Write the SHA-256 of everything after the user block into the user block of a file on disk; return it."""
    with open(path, "r+b") as fh:
        fh.seek(USERBLOCK)
        block = checksum_block(fh.read())
        fh.seek(0)
        fh.write(block)
    return block[len(STAMP) : len(STAMP) + 64].decode()


MAX_BYTES = 4 << 30  # a results file larger than this is not one vehid wrote (and would take minutes to check)


def _regular_fd(path: str | Path) -> int:
    """A read-only descriptor of `path` if it is a regular file (a FIFO never blocks the open); InputError naming
    it otherwise. FileNotFoundError passes through."""
    source = str(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise InputError(f"cannot read the file ({exc.strerror})", source=source) from None
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        kind = "a directory" if stat.S_ISDIR(mode) else "not a regular file (a FIFO, a device or a socket)"
        raise InputError(f"is {kind}, expected a results file", source=source)
    return fd


def check_integrity(path: str | Path) -> str | None:
    """InputError naming the file if it carries a vehid checksum its bytes no longer match (or a damaged one);
    the checksum when it matches; None for an HDF5 file without one (written before checksums, or by another
    tool: HDF5 then reports what it finds)."""
    source = str(path)
    fd = _regular_fd(path)
    try:
        size = os.fstat(fd).st_size
        if size > MAX_BYTES:
            raise InputError(f"is {size} bytes, larger than any results file vehid writes ({MAX_BYTES})", source=source)
        with os.fdopen(os.dup(fd), "rb") as fh:
            head = fh.read(USERBLOCK)
            digest = hashlib.sha256()
            while chunk := fh.read(1 << 20):
                digest.update(chunk)
        body = digest.hexdigest()
    except OSError as exc:
        raise InputError(f"cannot read the file ({exc.strerror})", source=source) from None
    finally:
        os.close(fd)
    if head.startswith(HDF5_SIGNATURE):
        return None
    if not head.startswith(STAMP):
        raise InputError(
            "not a readable results file: neither a vehid checksum nor an HDF5 signature at its start (damaged, "
            "truncated to nothing, or another kind of file)",
            source=source,
        )
    stored = head[len(STAMP) : len(STAMP) + 64].decode("ascii", "replace")
    if len(head) < USERBLOCK or stored != body:
        raise InputError(
            "damaged results file: its bytes do not match the SHA-256 checksum it was written with (truncated, "
            "partly copied, a disk error or an edit); rerun the campaign that wrote it",
            source=source,
        )
    return stored


_TREES: dict[FileIdentity, tuple[str | None, Tree]] = {}  # the files this process read, by identity and modification


def read_results(path: str | Path, what: str) -> tuple[str | None, Tree]:
    """(checksum or None, every part of the file as plain data) for a results file: its checksum verified, then
    parsed in a child process (`h5snapshot.read_tree`: no damage or crafting of its bytes can hang or crash vehid).
    A file read before and unchanged since is not read again. InputError naming the file; FileNotFoundError
    passes through."""
    source = str(path)
    try:
        key = file_identity(path)
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise InputError(f"cannot read the file ({exc.strerror})", source=source) from None
    if key not in _TREES:
        checksum = check_integrity(path)
        tree = read_tree(path, what)
        if len(_TREES) >= 64:
            _TREES.pop(next(iter(_TREES)))
        _TREES[key] = (checksum, tree)
    return _TREES[key]


def open_results(path: str | Path, kind: str, what: str) -> Tree:
    """A results file read for its readers (`read_results`), checking its kind; InputError for a missing,
    unreadable or other file. (A context manager, as the h5py file it replaces.)"""
    source = str(path)
    try:
        _, tree = read_results(path, what)
    except FileNotFoundError:
        raise InputError(f"{what} not found", source=source) from None
    found = tree.attrs.get("kind")
    if not isinstance(found, str) or found != kind:
        raise InputError(f"not a vehid {what} (kind {quote(found, 60)})", source=source)
    return tree


def save(path: str | Path, kind: str, result: Result, attrs: Mapping[str, str] | None = None) -> None:
    """A result in a checksummed vehid file of its own, written atomically: attributes kind, provenance and
    `attrs`, then the result's fields (`Result.write_h5`)."""
    with h5_file(path, userblock=USERBLOCK, head=checksum_block) as h5:
        h5.attrs["kind"] = kind
        for key, value in {**provenance(), **(attrs or {})}.items():
            h5.attrs[key] = value
        result.write_h5(h5)


def load(path: str | Path, kind: str, cls: type[Result], what: str = "results file") -> Result:
    """The result `save` wrote (its checksum verified first); InputError naming the file for a missing, damaged or
    foreign one."""
    with open_results(path, kind, what) as h5:
        try:
            return cls.read_h5(h5)
        except (KeyError, ValueError, TypeError, IndexError) as exc:  # a part missing or of another shape
            raise InputError(f"{what} is damaged or incomplete ({exc})", source=str(path)) from None
