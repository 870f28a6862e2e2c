"""core/jit: a compiled function cached on disk loads in a fresh process without numba's implementations (no
refresh of its target: no numba.np.linalg, no scipy.linalg), gives the numbers the compiling process gave, and falls
back to numba's own load when the quick one fails."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
from numba.core.registry import cpu_target

from tests.conftest import ROOT
from vehid_cli.core import jit

MODULE = textwrap.dedent('''
    import numpy as np
    from vehid_cli.core.jit import cached_njit

    @cached_njit(error_model="numpy")
    def damped(x0, c, n):
        """A damped oscillator by semi-implicit Euler (allocates: the runtime is needed), its last n states."""
        out = np.empty((n, 2))
        x, v = x0, 0.0
        for k in range(n):
            v += 0.01 * (-x - c * v)
            x += 0.01 * v
            out[k, 0] = x
            out[k, 1] = v
        return out
''')

PROBE = (
    "import json, sys; import numpy as np; from cached_probe import damped; out = damped(1.0, 0.3, 500); "
    "print(json.dumps({'out': out.tolist(), 'hits': sum(damped.stats.cache_hits.values()), "
    "'loaded': [m for m in ('numba.np.linalg', 'numba.np.arraymath', 'scipy.linalg') if m in sys.modules]}))"
)


def _probe(where) -> dict:
    env = {**os.environ, "PYTHONPATH": f"{where}{os.pathsep}{ROOT}"}
    run = subprocess.run([sys.executable, "-c", PROBE], cwd=ROOT, capture_output=True, text=True, check=True, env=env)
    return json.loads(run.stdout)


def _reference(n: int) -> np.ndarray:
    """The same recursion in Python (the same operations in the same order: bit for bit)."""
    out, x, v = np.empty((n, 2)), 1.0, 0.0
    for k in range(n):
        v += 0.01 * (-x - 0.3 * v)
        x += 0.01 * v
        out[k] = x, v
    return out


def test_a_cached_function_loads_in_a_fresh_process_without_numbas_implementations(tmp_path):
    (tmp_path / "cached_probe.py").write_text(MODULE)
    compiled = _probe(tmp_path)  # compiles (numba's compiler refreshes its target) and writes the cache
    loaded = _probe(tmp_path)  # loads it
    assert compiled["hits"] == 0 and loaded["hits"] == 1
    assert "numba.np.linalg" in compiled["loaded"]  # the probe sees the refresh where there is one
    assert loaded["loaded"] == []
    assert np.array_equal(np.array(loaded["out"]), np.array(compiled["out"]))
    assert np.array_equal(np.array(loaded["out"]), _reference(500))


def test_a_failed_quick_load_falls_back_to_numbas_refresh_and_load(monkeypatch):
    calls = []
    quick = jit.QuickLoadCache._load_overload

    def failing_once(self, sig, target_context):
        calls.append(sig)
        if len(calls) == 1:
            raise RuntimeError("a symbol the refresh installs")
        return quick(self, sig, target_context)

    refreshed = []
    monkeypatch.setattr(jit.QuickLoadCache, "_load_overload", failing_once)
    monkeypatch.setattr(jit.FunctionCache, "load_overload",
                        lambda self, sig, ctx: refreshed.append(sig) or quick(self, sig, ctx))  # fmt: skip
    cache = jit.QuickLoadCache(_reference)
    assert cache.load_overload((), cpu_target.target_context) is None  # nothing cached for it: a miss either way
    assert calls == [()] and refreshed == [()]  # the quick load failed once, numba's own load was asked


def test_the_compile_options_key_the_cache_and_compiled_functions_release_the_gil():
    """numba keys its index by the bytecode only: a function whose options changed (not its file) would load the old
    machine code. Ours are keyed by the options too; and they run without the GIL (candidate fits run in threads)."""
    codegen = cpu_target.target_context.codegen()
    sig = ("float64",)
    with_gil = jit.QuickLoadCache(_reference, {"nogil": False})._index_key(sig, codegen)
    without = jit.QuickLoadCache(_reference, {"nogil": True})._index_key(sig, codegen)
    assert with_gil != without
    assert with_gil[:-1] == without[:-1]  # numba's own key is the same: only the options tell them apart
    assert jit.cached_njit()(_reference).targetoptions["nogil"] is True
    assert jit.cached_njit(nogil=False)(_reference).targetoptions["nogil"] is False
