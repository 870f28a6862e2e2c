"""Every damper model's fast path (batch 20, 3000 RK4 steps) in this tree against another tree's laws and loop, in ONE
process, alternating call by call (a benchmark, not a test; issue 26).

On a VM whose speed swings from minute to minute, two runs of `bench_damper.py` cannot be compared, and even processes
alternated seconds apart differ by 1.5x. Here the other tree's batch laws (`vehid_cli/models/damper.py`) and their RK4
loop (`vehid_cli/sim/prescribed.py`, with the modules it imports from its own `sim/`) are loaded from its files under
private package names, and each pair of calls (the other tree first) runs within milliseconds on the same inputs: this
tree's `simulate_damper` prepares the bench (the other tree's loop must take the same arguments). Prints each model's
evaluations per CPU second in both trees, the median of the pairs' ratios, and whether the forces are the same bit for
bit (an intended change of the numbers is reported, not refused).
Run: NUMBA_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 \
     python benchmarks/bench_damper_against.py --against /path/to/other/checkout [--pairs 15] [--only force_map]
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import statistics
import sys
import types
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
import vehid_cli.sim.bench as bench_module  # noqa: E402
from benchmarks.bench_damper import CASES, alternated, rows_of, spec_of  # noqa: E402
from benchmarks.machine import host  # noqa: E402
from vehid_cli.models.bench import sawtooth, sine  # noqa: E402
from vehid_cli.sim.prescribed import integrate_lanes  # noqa: E402


def other_tree(tree: Path) -> tuple[types.ModuleType, types.ModuleType]:
    """The other tree's damper laws and prescribed-motion loop, imported from its files as `_other_models.damper` and
    `_other_sim.prescribed` (their relative imports resolve in the other tree's folders)."""
    for package, folder in (("_other_models", "models"), ("_other_sim", "sim")):
        module = types.ModuleType(package)
        module.__path__ = [str(tree / "vehid_cli" / folder)]
        sys.modules[package] = module
    return importlib.import_module("_other_models.damper"), importlib.import_module("_other_sim.prescribed")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", required=True, type=Path, help="the other tree (a checkout or an archive)")
    parser.add_argument("--pairs", type=int, default=15)
    parser.add_argument("--batch", type=int, default=20)
    parser.add_argument("--only", default="", help="only the models whose label contains this")
    args = parser.parse_args()
    other_laws, other_loop = other_tree(args.against.resolve())
    histories = {"sine": sine(0.025, 0.8, 2.4, 1e-3), "sawtooth": sawtooth(cycles=4.5)}
    print(f"# {host()}, python {sys.version.split()[0]}; batch {args.batch}, 3000 RK4 steps; {args.pairs} pairs")
    print(f"# this tree against {args.against}")
    print(f"{'model':<42} {'this tree':>10} {'other':>10} {'this/other':>10}  same forces")
    for label, (model, table, values, history) in CASES.items():
        if args.only not in label:
            continue
        spec, h = spec_of(model, table, values), histories[history]
        rows = rows_of(spec, args.batch)
        ours = spec.damper
        theirs = dataclasses.replace(ours, lanes=getattr(other_laws, ours.lanes.py_func.__name__))
        loops = {"this": (ours, integrate_lanes), "other": (theirs, other_loop.integrate_lanes)}

        def run(which: str, loops=loops, rows=rows, h=h) -> np.ndarray:
            damper, integrate = loops[which]
            bench_module.integrate_lanes = integrate  # the loop simulate_damper calls
            try:
                return bench_module.simulate_damper(damper, rows, h.t, h.x, h.v, h.u).force
            finally:
                bench_module.integrate_lanes = integrate_lanes

        same = np.array_equal(run("this"), run("other"), equal_nan=True)
        rates = alternated({"other": lambda: run("other"), "this": lambda: run("this")}, args.pairs, args.batch)
        ratio = statistics.median(t / o for t, o in zip(rates["this"], rates["other"], strict=True))
        this, other = statistics.median(rates["this"]), statistics.median(rates["other"])
        print(f"{label:<42} {this:>10.0f} {other:>10.0f} {ratio:>10.2f}  {'yes' if same else 'NO'}")


if __name__ == "__main__":
    main()
