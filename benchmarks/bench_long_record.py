"""A long logger record identified to the bound (issue 13): a 60 s four-post rig run at 1 kHz (60 000 samples x
16 channels plus the 4 actuators, MDF4 with 200 Hz potentiometers, g and mm, offsets) identified with `lsq`
through the CLI, as a user runs it. Target: <= 15 s wall on 2 cores, peak memory (process tree) <= 1 GB, and the
estimate within the bound (its z-scores printed). A benchmark, not a test.

Run: python benchmarks/bench_long_record.py [--repeats 3] [--duration 60]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.bench_campaign import timed_run  # noqa: E402
from examples.make_rig_runs import write_rig_run  # noqa: E402
from vehid_cli.config import load_config  # noqa: E402
from vehid_cli.systems import build_system  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RIG = ROOT / "configs" / "examples" / "four_post_rig.yaml"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--duration", type=float, default=60.0)
    args = parser.parse_args()
    print(f"# {platform.node()} {platform.machine()}, {os.cpu_count()} cores, python {platform.python_version()}")
    sets = [f"simulation.duration={args.duration:g}", "identify.truth=config"]
    with tempfile.TemporaryDirectory() as tmp:
        run = write_rig_run(RIG, Path(tmp) / "long.mf4", 5, sets[:1])
        print(f"{run.name}: {run.stat().st_size / 1e6:.1f} MB, {args.duration:g} s at 1 kHz")
        walls, peaks = [], []
        for k in range(args.repeats):
            out = Path(tmp) / f"fit{k}.h5"
            cli = ["identify", str(RIG), "--data", str(run), "-o", str(out), "--json", str(out.with_suffix(".json"))]
            wall, peak = timed_run([*cli, *sum((["--set", s] for s in sets), [])])
            walls.append(wall)
            peaks.append(peak)
        doc = json.loads(out.with_suffix(".json").read_text())
        system = build_system(load_config(RIG, sets), run)
        bound = system.bound()
        estimate = np.array([doc["mean"][n] for n in doc["parameters"]])
        z = (estimate - system.box.truth) / bound.sd
    label = f"identify lsq, {args.duration:g} s record"
    runs = ", ".join(f"{w:.2f}" for w in walls)
    print(f"{label:<40} median wall {statistics.median(walls):6.2f} s  (runs: {runs}); peak tree RSS "
          f"{max(peaks) / 2**20:.0f} MiB")  # fmt: skip
    scores = " ".join(f"{n} {v:+.2f}" for n, v in zip(doc["parameters"], z, strict=True))
    print(f"{'z-scores (estimate - truth) / CRLB sd':<40} {scores}")
    print(f"{'evaluations':<40} {doc['evaluations_per_run']}, CRLB NRE {bound.nre_rms_percent:.4f} %")


if __name__ == "__main__":
    main()
