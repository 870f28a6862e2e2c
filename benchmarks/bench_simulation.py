"""Model evaluations per second of the full-car simulation paths (a benchmark, not a test).

One evaluation = one parameter set simulated over the paper's experiment (3000 samples, 4 channels).
Each figure is the median of several repeats; the machine is noisy, so compare medians only.
Run: make bench   (or: python benchmarks/bench_simulation.py --repeats 7)
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time
from pathlib import Path

import numpy as np
from scipy import signal

from vehid_cli.config import load_config
from vehid_cli.experiment import build_experiment

ROOT = Path(__file__).resolve().parents[1]


def timed(fn, repeats: int) -> float:
    """Median wall time [s] of fn() over `repeats` calls, after one warm-up call."""
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    cfg = load_config(ROOT / "configs" / "gokdag2015" / "base.yaml")
    exp = build_experiment(cfg)
    rng = np.random.default_rng(0)
    print(f"# {platform.node()} {platform.processor() or platform.machine()}, python {platform.python_version()}")
    print(f"# experiment: {exp.t.size} samples, dt = {exp.dt * 1e3:g} ms, 4 acceleration channels")
    print(f"{'path':<28} {'batch':>5} {'median s/call':>14} {'evals/s':>10}")

    rows = []
    for integrator in ("exact", "newmark"):
        exp_i = build_experiment(
            cfg.model_copy(update={"simulation": cfg.simulation.model_copy(update={"integrator": integrator})})
        )
        for batch in (1, 20):
            values = {"m": 1300 * rng.uniform(0.7, 1.3, batch), "Ix": 500 * rng.uniform(0.7, 1.3, batch)}
            seconds = timed(lambda e=exp_i, v=values: e.simulate(v).acc, args.repeats)
            rows.append((f"numpy {integrator}", batch, seconds, batch / seconds))

    mats = exp.matrices()
    A, Bs = mats.state_space()
    Cd = np.zeros((4, 14))
    Cd[:, :3] = mats.G
    system = (A, Bs, Cd, np.zeros((4, 4)))
    seconds = timed(lambda: signal.lsim(system, exp.road, exp.t), args.repeats)
    rows.append(("scipy.signal.lsim", 1, seconds, 1 / seconds))
    for name, batch, seconds, rate in rows:
        print(f"{name:<28} {batch:>5} {seconds:>14.4f} {rate:>10.1f}")


if __name__ == "__main__":
    main()
