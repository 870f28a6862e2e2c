"""The linear car's identification path (``Experiment.outputs``, exact integrator, the paper's 3000 samples) in this
tree against another tree, alternated process by process on ONE core (a benchmark, not a test; issue 26).

On a VM whose speed swings from minute to minute the figures of two separate runs cannot be compared; here each pair
of processes (the other tree first) runs within seconds, and the ratio of each pair is printed with their median.
Each process times repeated calls for --seconds and prints evaluations/s at batch 20 and 100.
Run: python benchmarks/bench_linear_against.py --against /path/to/other/checkout [--pairs 8] [--seconds 3]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BATCHES = (20, 100)

CHILD = """
import os, sys, time
sys.path.insert(0, {tree!r})
import numpy as np
from vehid_cli.config import load_config
from vehid_cli.identify.experiment import build_experiment
from vehid_cli.sim.kernel import set_threads
set_threads(1)
cfg = load_config({config!r})
exp = build_experiment(cfg)
rng = np.random.default_rng(0)
base = cfg.vehicle.values()
rates = []
for batch in {batches!r}:
    values = {{k: base[k] * rng.uniform(0.7, 1.3, batch) for k in cfg.identify.unknowns}}
    exp.outputs(values)
    start, calls = time.perf_counter(), 0
    while time.perf_counter() - start < {seconds!r}:
        exp.outputs(values)
        calls += 1
    rates.append(batch * calls / (time.perf_counter() - start))
print(*rates)
"""


def rates(tree: Path, seconds: float) -> list[float]:
    """Evaluations/s at each of BATCHES of the tree's identification path, in a fresh one-thread process."""
    env = dict(os.environ, NUMBA_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
    code = CHILD.format(tree=str(tree), config=str(ROOT / "configs" / "gokdag2015" / "base.yaml"),
                        batches=BATCHES, seconds=seconds)  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    return [float(x) for x in out.stdout.split()]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--against", type=Path, required=True, help="the other checkout (its vehid_cli is timed)")
    parser.add_argument("--pairs", type=int, default=8)
    parser.add_argument("--seconds", type=float, default=3.0)
    args = parser.parse_args()
    pairs = [(rates(args.against, args.seconds), rates(ROOT, args.seconds)) for _ in range(args.pairs)]
    print(f"# {args.pairs} pairs, {args.seconds:g} s per batch size per process; this tree: {ROOT}")
    for i, batch in enumerate(BATCHES):
        that = [p[0][i] for p in pairs]
        this = [p[1][i] for p in pairs]
        ratios = [a / b for b, a in zip(that, this, strict=True)]
        print(
            f"batch {batch:>3}: this tree median {statistics.median(this):7.0f}/s, {args.against} "
            f"{statistics.median(that):7.0f}/s; pair ratios "
            + " ".join(f"{r:.2f}" for r in ratios)
            + f"; median {statistics.median(ratios):.2f}"
        )


if __name__ == "__main__":
    main()
