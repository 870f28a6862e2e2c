"""HDF5 files built in memory and written with ordinary, atomic file I/O.

HDF5 reports a failed write (a full disk) from inside the library, sometimes only while it closes the file in a
destructor, where h5py can neither raise it nor clean up: warnings "Exception ignored", then a crash. So every
vehid HDF5 file is built with the in-memory core driver, and its bytes are written by `data.write_bytes`, where a
full disk is a Python `OSError` (`errors.DiskFull` naming the file).
"""

from __future__ import annotations

import contextlib
import itertools
from collections.abc import Callable, Iterator
from pathlib import Path

import h5py

from .files import write_bytes

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
