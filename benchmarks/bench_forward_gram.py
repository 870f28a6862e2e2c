"""A long record's forward-difference normal equations: summed in time blocks (identify/forward.forward_gram, the
new path) beside the anchor, the held Jacobian (the D + 1 cars' residuals at the kept entries, then [J r]'[J r]: the
path of lsq.polish and fisher_ci before), on one simulated RK4 record with a hold-out split (a benchmark, not a
test). Prints each path's median wall over `--repeats` (interleaved) and its traced peak (tracemalloc, NumPy's
arrays), and their ratios.
Run: python benchmarks/bench_forward_gram.py [--seconds 60] [--repeats 3]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from vehid_cli.config import load_config  # noqa: E402
from vehid_cli.diagnose.holdout import holdout_blocks  # noqa: E402
from vehid_cli.identify.forward import forward_gram  # noqa: E402
from vehid_cli.identify.task import build_task  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    sets = ["identify.objective=wls", "noise.level=0.03", f"simulation.duration={args.seconds}",
            "simulation.integrator=rk4", "road.bump=null", "road.random.iso_class=C"]  # fmt: skip
    task = build_task(load_config(ROOT / "configs" / "gokdag2015" / "base.yaml", sets))
    task = task.with_unknowns(("kf", "kr", "cf", "cr"))  # D = 9, as the diagnosis's re-fit
    ref = task.reference(0)
    problem, objective = task.problem(ref), task.objective(ref)
    x = task.nominal
    step = 1e-7 * (task.upper - task.lower)
    X = np.vstack([x[None, :], x[None, :] + np.diag(step)])
    rows = np.flatnonzero(~np.resize(holdout_blocks(task.residual_samples // 2), task.residual_samples))
    values = {n: X[:, j] for j, n in enumerate(task.names)}

    def held() -> np.ndarray:
        R = problem.kept(X, rows)
        R[1:] -= R[0]
        R[1:] /= step[:, None]
        A = np.vstack([R[1:], R[:1]])
        return A @ A.T

    def summed() -> np.ndarray:
        return forward_gram(task.experiment, objective, values, step, rows)

    walls: dict[str, list[float]] = {"held (anchor)": [], "summed": []}
    peaks: dict[str, int] = {}
    grams = {}
    for name, run in (("held (anchor)", held), ("summed", summed)):  # compiled and cached first
        tracemalloc.start()
        grams[name] = run()
        peaks[name] = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    for _ in range(args.repeats):
        for name, run in (("held (anchor)", held), ("summed", summed)):
            t0 = time.perf_counter()
            run()
            walls[name].append(time.perf_counter() - t0)
    d = np.sqrt(np.diag(grams["held (anchor)"]))
    diff = np.max(np.abs(grams["summed"] - grams["held (anchor)"]) / np.outer(d, d))
    print(f"{args.seconds:g} s record, D = {task.dim}, {rows.size} kept entries; Gram difference {diff:.1e} (relative)")
    for name in walls:
        wall, peak = statistics.median(walls[name]), peaks[name] / 2**20
        print(f"  {name:14s} median {wall:6.2f} s, traced peak {peak:6.1f} MiB")
    w = statistics.median(walls["summed"]) / statistics.median(walls["held (anchor)"])
    print(f"  summed / held: wall x{w:.2f}, traced peak x{peaks['summed'] / peaks['held (anchor)']:.2f}")


if __name__ == "__main__":
    main()
