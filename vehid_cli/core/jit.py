"""Compiled functions: numba's ``njit`` with its on-disk cache, loaded without numba's library of implementations.

numba refreshes its target before it loads a cached function: it imports every implementation it has (arrays, linear
algebra, random, typed containers ...; scipy.linalg for its BLAS check, which walks numpy's namespace), 0.15-0.25 s
of each command's start. A cached function is machine code already: loading it needs numba's runtime (NRT, the
allocator its arrays use) and the symbols numba installs when it starts, not the implementations, which only
compiling reads (numba's compiler refreshes the target itself, so a cache miss compiles as before)."""

from __future__ import annotations

import hashlib
from collections.abc import Callable

import numba
from numba.core.caching import FunctionCache
from numba.core.runtime import rtsys


class QuickLoadCache(FunctionCache):
    """numba's on-disk function cache (same files), loading without refreshing the target first; if a load fails that
    way, numba's own (refresh, then load) is tried before giving up. Its index is also keyed by the compile options
    (`options`): numba's is not, so a function whose options changed but not its file loaded the old machine code."""

    def __init__(self, py_func, options: dict | None = None):
        super().__init__(py_func)
        self._options = repr(sorted((options or {}).items()))

    def _index_key(self, sig, codegen):
        return (*super()._index_key(sig, codegen), self._options)

    def load_overload(self, sig, target_context):
        rtsys.initialize(target_context)  # the runtime the compiled code allocates with (idempotent)
        try:
            with self._guard_against_spurious_io_errors():
                return self._load_overload(sig, target_context)
        except Exception:  # noqa: BLE001 - something the code needs comes with the refresh: numba's way
            return super().load_overload(sig, target_context)


class KeyedCache(QuickLoadCache):
    """The cache keyed by our own digest instead of the closure's pickled cells (which hold freshly made
    dispatchers, so numba's own key differs in every process and the cache never hits): for loops compiled per
    force law (``sim.rk4``, ``sim.prescribed``), `key` a digest of the sources they are made of."""

    def __init__(self, py_func, key: str):
        super().__init__(py_func)
        self._key = key  # (the loops' options are in their sources, which the key digests)

    def _index_key(self, sig, codegen):
        return (sig, codegen.magic_tuple(), (hashlib.sha256(self._py_func.__code__.co_code).hexdigest(), self._key))


def cached_njit(**options) -> Callable:
    """``numba.njit(cache=True, nogil=True, **options)`` with the cache a ``QuickLoadCache``: the decorator of every
    compiled function of the package that does not take a function as an argument (those are not cacheable,
    numba#9237). Without the GIL by default: the diagnosis fits its candidates in threads, and a compiled loop that
    held it (the exact linear car's modal recursions, its sensitivities) ran them one at a time."""
    options = {"nogil": True, **options}

    def decorate(fn):
        dispatcher = numba.njit(**options)(fn)
        dispatcher._cache = QuickLoadCache(dispatcher.py_func, options)
        return dispatcher

    return decorate
