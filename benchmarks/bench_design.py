"""Wall time of a full `vehid design` of the paper's case (a benchmark, not a test).

Target (issue 14): the design of configs/gokdag2015/design.yaml (speed, left/right heights, two shapes, length,
duration; criterion nre) in <= 30 s on 2 cores, end to end through the CLI (process start, imports, the search,
the profiles for the figures, the table; --plots and --json written). Reports the median over --repeats.
Run: python benchmarks/bench_design.py [--repeats 3] [--jobs N]
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DESIGN = ROOT / "configs" / "gokdag2015" / "design.yaml"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--jobs", type=int, default=None, help="worker processes (default: all cores)")
    args = parser.parse_args()
    print(f"# {platform.node()} {platform.machine()}, {os.cpu_count()} cpus, python {platform.python_version()}")
    walls, searches = [], []
    for _ in range(args.repeats):
        with tempfile.TemporaryDirectory() as tmp:
            doc = Path(tmp) / "design.json"
            cmd = [sys.executable, "-m", "vehid_cli", "design", str(DESIGN), "--json", str(doc), "--plots", tmp,
                   "-o", str(Path(tmp) / "best.yaml")]  # fmt: skip
            if args.jobs:
                cmd += ["--jobs", str(args.jobs)]
            start = time.perf_counter()
            subprocess.run(cmd, cwd=ROOT, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            walls.append(time.perf_counter() - start)
            d = json.loads(doc.read_text())
            searches.append(d["search"]["wall_s"])
    runs = ", ".join(f"{w:.1f}" for w in walls)
    print(
        f"design of the paper's case ({d['search']['evaluations']} bounds, {d['search']['jobs']} jobs)  "
        f"median wall {statistics.median(walls):6.1f} s  (runs: {runs}); inside the library "
        f"{statistics.median(searches):.1f} s; NRE bound {d['configured']['nre_rms_percent']:.3f} % -> "
        f"{d['designed']['nre_rms_percent']:.3f} % ({d['improvement']['nre']:.2f}x)"
    )


if __name__ == "__main__":
    main()
