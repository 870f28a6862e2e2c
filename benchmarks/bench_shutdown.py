"""How long a `vehid` process takes to end after its command is done (a benchmark, not a test).

A command's last Python-level exit hook runs when the command is done and its outputs written; what follows is the
interpreter's shutdown (modules cleared, what they held freed), which the user waits for too. Each case is run in a
fresh process as `python -c` importing the console script's `main` beside an atexit hook registered before it (so it
runs after the command's own hooks): the hook prints the time since start, the process's wall is taken from outside;
shutdown = wall - hook time. Printed beside the anchor `vehid --help` (median wall, timed in the same run), and with
`--against DIR` the same for the source tree DIR (e.g. an archive of an earlier commit), runs interleaved.
Run: python benchmarks/bench_shutdown.py [--repeats 5] [--against DIR] [--data RUN.csv]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASE = ROOT / "configs" / "gokdag2015" / "base.yaml"
PROBE = (
    "import atexit, sys, time; t0 = time.perf_counter(); "
    "atexit.register(lambda: print(f'hook {time.perf_counter() - t0:.6f}', file=sys.stderr)); "
    "sys.argv = ['vehid', *sys.argv[1:]]; from vehid_cli.__main__ import main; main()"
)


def timed(root: Path, *args: str) -> tuple[float, float]:
    """(wall [s], the command's end [s after the interpreter ran its first line]) of `vehid args` on tree `root`."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env["PYTHONPATH"] = str(root)
    start = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", PROBE, *args], cwd=root, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if res.returncode:
        raise SystemExit(res.stderr[-2000:])
    hook = float(next(line for line in res.stderr.splitlines() if line.startswith("hook ")).split()[1])
    return wall, hook


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--against", type=Path, help="another source tree, timed interleaved with this one")
    parser.add_argument("--data", type=Path, help="the run to diagnose (default: simulated from the base config)")
    args = parser.parse_args()
    trees = [ROOT] + ([args.against.resolve()] if args.against else [])
    print(f"# {os.cpu_count()} cpus, load average {os.getloadavg()[0]:.1f}")
    with tempfile.TemporaryDirectory() as tmp:
        data = args.data
        if data is None:
            data = Path(tmp) / "run.csv"
            subprocess.run([sys.executable, "-m", "vehid_cli", "simulate", str(BASE), "-o", str(data), "--set",
                            "noise.level=0.05"], cwd=ROOT, check=True, capture_output=True)  # fmt: skip
        commands = {"vehid --help": ("--help",), "vehid diagnose (3 s)": ("diagnose", str(BASE), "--data", str(data))}
        anchor: dict[Path, float] = {}
        for name, command in commands.items():
            runs: dict[Path, list[tuple[float, float]]] = {t: [] for t in trees}
            for _ in range(args.repeats):
                for t in trees:
                    runs[t].append(timed(t, *command))
            for t in trees:
                wall = statistics.median(w for w, _ in runs[t])
                shutdown = statistics.median(w - h for w, h in runs[t])
                anchor.setdefault(t, wall)  # the first command's: vehid --help
                label = "this tree" if t == ROOT else str(t)
                print(
                    f"{name} [{label}]: median wall {wall:.2f} s (anchor vehid --help {anchor[t]:.2f} s), of it "
                    f"shutdown after the command {shutdown:.3f} s ({', '.join(f'{w - h:.2f}' for w, h in runs[t])})"
                )


if __name__ == "__main__":
    main()
