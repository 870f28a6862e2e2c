"""Keep freed working memory in the process (glibc's malloc): every model evaluation allocates arrays of a few MB
(the modal coordinates, the sensitivities' drive and lanes, the channels), and by default glibc serves each from a
fresh mmap and returns it on free, so every evaluation pays the kernel's page faults and zeroing again — measured
4x the exact sensitivities' cost (8.4 -> 2.2 ms per call on the paper's case) and up to 2x a batch-20 simulation.

`keep_freed_memory` raises the mmap threshold to MMAP_THRESHOLD (blocks below it come from the heap and are reused)
and the trim threshold to TRIM_THRESHOLD (free heap up to it stays mapped). The peak is unchanged: a block still
needs memory only while it lives; what changes is that its pages are not handed back and faulted in again. Larger
blocks (a long record's whole-record arrays) keep glibc's mmap path, so they are returned at once. A no-op where the
C library is not glibc.

A long record is the opposite case (`hand_back_freed_memory`, set when one is loaded): its arrays are tens of MB, few
per evaluation, and a diagnosis runs phases of different shapes one after the other (the declared fit's, the missing
force's columns, candidate fits in threads, each with its own malloc arena); with 64 MiB kept per arena the freed
memory of one phase stayed mapped under the next one's (the 60 s diagnosis peaked 87 MiB higher: 432 vs 345 MiB).
Lower thresholds (LONG_MMAP_THRESHOLD, LONG_TRIM_THRESHOLD) hand it back, and fewer arenas (LONG_ARENA_MAX) keep
less of it in the threads' own; the page faults they cost are small beside a long record's evaluation.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import sys

M_TRIM_THRESHOLD = -1  # glibc's mallopt parameter numbers (malloc.h)
M_MMAP_THRESHOLD = -3
M_ARENA_MAX = -8
MMAP_THRESHOLD = 32 * 2**20  # [bytes] blocks below this come from the heap (glibc's default starts at 128 kB)
TRIM_THRESHOLD = 64 * 2**20  # [bytes] free heap kept mapped for reuse (glibc's default starts at 128 kB)
LONG_MMAP_THRESHOLD = 4 * 2**20  # [bytes] the same for a long record (`hand_back_freed_memory`)
LONG_TRIM_THRESHOLD = 8 * 2**20
LONG_ARENA_MAX = 1  # malloc arenas for a long record (glibc's default: 8 per core): one, which every thread shares


def keep_freed_memory() -> bool:
    """Set glibc's mmap and trim thresholds (see the module docstring); True when they were set."""
    return _thresholds(MMAP_THRESHOLD, TRIM_THRESHOLD)


_STATE = {"handing_back": False}  # set once a long record is loaded (`hand_back_freed_memory`)


def hand_back_freed_memory() -> bool:
    """Lower glibc's thresholds and arena count for a long record (see the module docstring); True when set."""
    _STATE["handing_back"] = True
    return _thresholds(LONG_MMAP_THRESHOLD, LONG_TRIM_THRESHOLD, LONG_ARENA_MAX)


def release_if_handing_back() -> bool:
    """`release_free_pages` once a long record has been loaded (`hand_back_freed_memory`), else nothing (a short
    record's freed memory is kept for reuse, by design): a phase of a long record's work that is not itself blocked
    over the record (the missing force's estimate on its screening window: 30 MiB freed inside the heap) hands its
    freed pages back before the next one. True when they were released."""
    return _STATE["handing_back"] and release_free_pages()


def _thresholds(mmap_bytes: int, trim_bytes: int, arenas: int | None = None) -> bool:
    """glibc's mmap threshold and trim threshold [bytes] (and the most arenas, when given) set by mallopt; False
    where that is not glibc's."""
    libc = _libc()
    try:
        mallopt = libc.mallopt
    except AttributeError:  # no C library found, or one without mallopt (musl)
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    done = bool(mallopt(M_MMAP_THRESHOLD, mmap_bytes)) and bool(mallopt(M_TRIM_THRESHOLD, trim_bytes))
    return done and (arenas is None or bool(mallopt(M_ARENA_MAX, arenas)))


def release_free_pages() -> bool:
    """Hand the free pages inside glibc's heaps back to the system (malloc_trim(0): every arena, not only the memory
    above the top chunk that the trim threshold governs). A long record's evaluation calls it when done: the compiled
    kernels' and the blocks' small allocations interleave with its arrays, so freed memory in the middle of a heap
    stays mapped otherwise, and the floor under every later phase rises. False where that is not glibc's."""
    libc = _libc()
    if libc is None:
        return False
    try:
        trim = libc.malloc_trim
    except AttributeError:
        return False
    trim.argtypes = (ctypes.c_size_t,)
    trim.restype = ctypes.c_int
    trim(0)
    return True


@functools.cache
def _libc():
    """The C library (Linux), or None."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        return ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
    except OSError:
        return None
