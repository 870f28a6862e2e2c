"""Wall time of `vehid check` on the four-post rig example as a user runs it (a benchmark, not a test).

Target (issue 21): under 2 s for the example's 16 channels (8 s at 1 kHz, the potentiometers at 200 Hz) with a
per-channel table. The run is written once by `examples/make_rig_runs.py`; `vehid check` then runs in a fresh
process each time (imports included), `--repeats` times, and the median is reported with the time inside the library
(reading the file, the configured car's prediction, the checks). One warm-up run first, not counted: it writes the
bytecode and numba caches a user's second run finds (PYTHONDONTWRITEBYTECODE is unset for the timed process, as on a
user's machine). Run: python benchmarks/bench_check.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RIG = ROOT / "configs" / "examples" / "four_post_rig.yaml"
sys.path.insert(0, str(ROOT))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    vehid = Path(sys.executable).with_name("vehid")
    with tempfile.TemporaryDirectory() as tmp:
        make = [sys.executable, str(ROOT / "examples" / "make_rig_runs.py"), str(RIG), "-o", tmp, "--runs", "1"]
        subprocess.run(make, check=True, capture_output=True)
        run = Path(tmp) / "rig_run1.mf4"
        env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        command = [str(vehid), "check", str(RIG), "--data", str(run)]
        subprocess.run(command, capture_output=True, env=env, check=True)  # warm-up: bytecode and numba caches
        walls = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            res = subprocess.run(command, capture_output=True, text=True, env=env)
            walls.append(time.perf_counter() - t0)
            assert res.returncode == 0 and "every check passed" in res.stdout, res.stdout + res.stderr
        from vehid_cli.systems import check_config

        inside = []
        for _ in range(args.repeats):
            t0 = time.perf_counter()
            check_config(RIG, (), run)
            inside.append(time.perf_counter() - t0)
    load = os.getloadavg()[0]
    print(f"# {platform.node()} {platform.machine()}, python {platform.python_version()}, load {load:.2f}")
    print(f"vehid check, four-post rig (16 channels, 8 s)  median wall {statistics.median(walls):5.2f} s  "
          f"(runs: {', '.join(f'{w:.2f}' for w in walls)}); inside the library {statistics.median(inside):.2f} s "
          f"(target 2 s)")  # fmt: skip


if __name__ == "__main__":
    main()
