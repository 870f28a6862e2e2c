"""A long record through the RK4 kernel in time blocks (issue 26) against one call over the record (a benchmark, not
a test): `Experiment.outputs` of a 60 s ISO-road record at 1 kHz with hysteresis struts, for batches of 1, 3 and 13
cars (one evaluation, a chunk of a Jacobian, a whole forward-difference Jacobian of 12 unknowns), the blocked path
(`sim.nonlinear.effects_blocks`: only the layout's channels kept) beside the anchor, `read(simulate(...))` (the whole
trajectories, what a long record ran before), timed interleaved in the same process, medians of `--repeats`; and the
traced peak of NumPy's memory of each (tracemalloc). The channels are compared bit for bit.
Run: python benchmarks/bench_blocks.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from vehid_cli.config import load_config  # noqa: E402
from vehid_cli.identify.task import build_task  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
LONG = ["road.bump=null", "road.random.iso_class=C", "simulation.duration=60", "simulation.integrator=rk4"]


def traced_peak(fn) -> float:
    """The peak of the memory traced by tracemalloc while fn() runs [MiB] (NumPy's arrays included)."""
    tracemalloc.start()
    try:
        fn()
        return tracemalloc.get_traced_memory()[1] / 2**20
    finally:
        tracemalloc.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    print(f"# {platform.node()} {platform.machine()}, {os.cpu_count()} cpus, python {platform.python_version()}, "
          f"load average {os.getloadavg()[0]:.1f}")  # fmt: skip
    exp = build_task(load_config(ROOT / "configs" / "effects" / "hysteresis.yaml", LONG)).experiment
    for P in (1, 3, 13):
        values = {"m": np.linspace(1200.0, 1300.0, P), "hysteresis.beta": np.linspace(1e4, 3e4, P)}
        assert exp.blocked(values)

        def blocked(values=values):
            return exp.outputs(values)

        def whole(values=values):
            return exp.read(exp.simulate(values))

        a, b = blocked(), whole()  # loaded and warmed up; the same channels
        assert all(np.array_equal(a[f], b[f]) for f in b)
        walls: dict[str, list[float]] = {"blocked": [], "whole": []}
        for _ in range(args.repeats):  # interleaved: the machine's load moves both
            for name, fn in (("whole", whole), ("blocked", blocked)):
                start = time.perf_counter()
                fn()
                walls[name].append(time.perf_counter() - start)
        w_b, w_w = statistics.median(walls["blocked"]), statistics.median(walls["whole"])
        print(f"{P:2d} cars, 60 s: blocks median {w_b * 1e3:.0f} ms, traced peak {traced_peak(blocked):.0f} MiB; "
              f"anchor one call {w_w * 1e3:.0f} ms, traced peak {traced_peak(whole):.0f} MiB; ratio {w_b / w_w:.2f}; "
              "channels bit-identical")  # fmt: skip


if __name__ == "__main__":
    main()
