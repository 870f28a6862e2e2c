"""Simulations and wall time of `vehid diagnose`'s candidate rounds (a benchmark, not a test; issue 26 acceptance 5).

Each case (a 3 s bump run with 5 % noise, simulated once by `vehid simulate`) is diagnosed in a fresh process with the
RK4 kernel wrapped to count the nonlinear car simulations (the sum of the batches' sizes), by the diagnose function
that asked for them, and the wall time of the whole command and of the loop's candidate rounds. `--against DIR` runs
the same on the source tree DIR (e.g. `git archive` of an earlier commit), its runs interleaved with this tree's; each
figure is printed beside that anchor with the ratio of the medians (this tree over DIR). BLAS pinned to one thread.
Run: python benchmarks/bench_candidate_fits.py [--repeats 3] [--against DIR]
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
HYSTERESIS = ["vehicle.effects.hysteresis.beta=3e3", "vehicle.effects.hysteresis.gamma=3e3"]
CASES = {  # name: (truth config, simulate --set overrides); each diagnosed with configs/gokdag2015/base.yaml
    "kf +20 %, cr -15 %": ("configs/gokdag2015/base.yaml", ["vehicle.kf=54000", "vehicle.cr=2975"]),
    "Bouc-Wen yielding at 13 mm": ("configs/effects/hysteresis.yaml", HYSTERESIS),
    "nothing missing": ("configs/gokdag2015/base.yaml", []),
}
ENV = {"NUMBA_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
PROBE = r"""
import collections, json, sys, time
import vehid_cli.sim.kernel as K
import vehid_cli.diagnose.loop as L
run, sims, by = K._run_rk4, [0], collections.Counter()
NAMES = ("screen_starts", "fisher_ci", "fit_free", "linear_fit", "effect_score", "score_statistics", "validation_J")
def counted(b, dt, force, out, *rest):
    sims[0] += b.P
    f = sys._getframe(1)
    while f is not None and f.f_code.co_name not in NAMES:
        f = f.f_back
    by[f.f_code.co_name if f is not None else "other"] += b.P
    return run(b, dt, force, out, *rest)
K._run_rk4 = counted
rank, rounds = L._Augmentation.rank, [0.0]
def timed_rank(self, todo):
    t = time.perf_counter(); out = rank(self, todo); rounds[0] += time.perf_counter() - t; return out
L._Augmentation.rank = timed_rank
from vehid_cli.cli.app import app
t0 = time.perf_counter()
try:
    app(sys.argv[2:])
except SystemExit:
    pass
got = {"wall": time.perf_counter() - t0, "rounds": rounds[0], "sims": sims[0], "by": dict(by)}
json.dump(got, open(sys.argv[1], "w"))
"""


def diagnose(root: Path, data: Path, out: Path) -> dict:
    """One `vehid diagnose` of `data` by the tree `root` with the probe; its figures and the JSON it wrote."""
    with tempfile.NamedTemporaryFile(suffix=".json") as f:
        env = {**os.environ, **ENV, "PYTHONPATH": str(root)}
        args = ["diagnose", "configs/gokdag2015/base.yaml", "--data", str(data), "--json", str(out)]
        subprocess.run([sys.executable, "-c", PROBE, f.name, *args], cwd=root, env=env, check=True,
                       capture_output=True)  # fmt: skip
        return json.loads(Path(f.name).read_text())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--against", type=Path, default=None)
    args = ap.parse_args()
    trees = {"this": ROOT} | ({"anchor": args.against.resolve()} if args.against else {})
    with tempfile.TemporaryDirectory() as tmp:
        for name, (truth, sets) in CASES.items():
            data = Path(tmp) / "data.csv"
            sim = ["simulate", truth, "-o", str(data), "--set", "noise.level=0.05"]
            for s in sets:
                sim += ["--set", s]
            subprocess.run([sys.executable, "-m", "vehid_cli", *sim], cwd=ROOT, check=True, capture_output=True,
                           env={**os.environ, "PYTHONPATH": str(ROOT)})  # fmt: skip
            got: dict[str, list[dict]] = {t: [] for t in trees}
            for _ in range(args.repeats):  # interleaved
                for t, root in trees.items():
                    got[t].append(diagnose(root, data, Path(tmp) / f"{t}.json"))
            print(f"{name}:")
            for key in ("sims", "wall", "rounds"):
                med = {t: statistics.median(r[key] for r in runs) for t, runs in got.items()}
                line = f"  {key:7s} this {med['this']:8.2f}"
                if "anchor" in med:
                    line += f"   anchor {med['anchor']:8.2f}   ratio {med['this'] / med['anchor']:.3f}"
                print(line)
            print("  simulations by caller (this):", got["this"][0]["by"])
            if "anchor" in got:
                print("  simulations by caller (anchor):", got["anchor"][0]["by"])
                a, b = (json.loads((Path(tmp) / f"{t}.json").read_text()) for t in ("anchor", "this"))
                same = a["verdict"] == b["verdict"]
                print("  selected", b["selected"], "anchor", a["selected"], "same verdict:", same)


if __name__ == "__main__":
    main()
