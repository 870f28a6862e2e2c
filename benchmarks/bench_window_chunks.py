"""Wall of a candidate fit's forward-difference batch on a long record's screening window (diagnose/window.py) by
how many cars are simulated at once (Experiment.chunk_bytes): the whole batch at once (CHUNK_BYTES, the anchor) beside
WINDOW_CHUNK_BYTES (and half of it), interleaved, medians of --repeats (a benchmark, not a test; issue 26).
Run: NUMBA_NUM_THREADS=1 python benchmarks/bench_window_chunks.py [--repeats 15] [--cars 13]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from vehid_cli.config import load_config  # noqa: E402
from vehid_cli.diagnose.window import SCREEN_SAMPLES, WINDOW_CHUNK_BYTES, window_task  # noqa: E402
from vehid_cli.identify.experiment import CHUNK_BYTES  # noqa: E402
from vehid_cli.identify.task import build_task  # noqa: E402
from vehid_cli.systems.vehicle.diagnosis import prepare_config  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
SETS = ["road.bump=null", "road.random.iso_class=C", "identify.objective=wls", "simulation.duration=12"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--cars", type=int, default=13)
    args = parser.parse_args()
    task = build_task(prepare_config(load_config(ROOT / "configs" / "effects" / "hysteresis.yaml", SETS)))
    head = window_task(task)
    ref = {f: v[:SCREEN_SAMPLES] for f, v in task.reference(0).items()}
    X = task.nominal * np.random.default_rng(2).uniform(0.95, 1.05, size=(args.cars, task.dim))
    sizes = {"whole batch (anchor)": CHUNK_BYTES, "WINDOW_CHUNK_BYTES": WINDOW_CHUNK_BYTES,
             "half of it": WINDOW_CHUNK_BYTES // 2}  # fmt: skip
    problems = {}
    for name, size in sizes.items():
        t = dataclasses.replace(head, experiment=dataclasses.replace(head.experiment, chunk_bytes=size))
        problems[name] = (t.problem(ref), t.experiment.cars_per_chunk)
        problems[name][0].residuals(X)  # compile and warm up
    walls = {name: [] for name in problems}
    for _ in range(args.repeats):
        for name, (problem, _) in problems.items():
            start = time.perf_counter()
            problem.residuals(X)
            walls[name].append(time.perf_counter() - start)
    anchor = statistics.median(walls["whole batch (anchor)"])
    print(f"# load {os.getloadavg()[0]:.1f}, NUMBA_NUM_THREADS={os.environ.get('NUMBA_NUM_THREADS', 'default')}, "
          f"{args.cars} cars on the {SCREEN_SAMPLES}-sample window, medians of {args.repeats}")  # fmt: skip
    for name, (_, chunk) in problems.items():
        wall = statistics.median(walls[name])
        print(f"{name}: {chunk} cars at a time, {1e3 * wall:.1f} ms; anchor (whole batch) {1e3 * anchor:.1f} ms; "
              f"ratio {wall / anchor:.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
