"""Campaign and sweep wall time, and the peak memory of the whole process tree (a benchmark, not a test).

Targets (issue 4): the paper's campaign (30 runs x 1000 evaluations, linear car) <= 20 s on 2 cores;
the Table 1 + 2 sweep (12 campaigns of the paper's algorithms, plus 4 of `hybrid`) <= 5 min; peak memory
of a sweep < 1 GB. Issue 12: `vehid --help` <= 0.3 s; the paper's 30-run `lsq` campaign end to end (process
wall) <= 2.5 s on 2 cores. Each command runs as a user runs it, through the CLI, in a fresh output directory.
Run: python benchmarks/bench_campaign.py [--repeats 3] [--sweep]
"""

from __future__ import annotations

import argparse
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASE = ROOT / "configs" / "gokdag2015" / "base.yaml"


def tree_sum_bytes(pid: int, file: str, field: str) -> int:
    """The kB figure `field` of /proc/PID/`file`, summed over a process and all its descendants, in bytes (Linux).

    A child that shares its parent's address space is not counted again: between vfork() and exec() (how
    subprocess starts every child: the logger file's reader, git for the provenance) the child's /proc figures are
    its parent's memory, which a sample caught in that window counted twice (a 60 s identify read 526 MiB once, 276
    otherwise). Such a child has its parent's /proc/PID/statm to the page; a process of its own does not."""
    total, stack = 0, [(pid, None)]
    while stack:
        p, parent = stack.pop()
        try:
            statm = _statm(p)
            if parent is None or statm != parent:
                with open(f"/proc/{p}/{file}") as fh:
                    total += sum(int(line.split()[1]) * 1024 for line in fh if line.startswith(field))
            for task in os.listdir(f"/proc/{p}/task"):
                with open(f"/proc/{p}/task/{task}/children") as fh:
                    stack.extend((int(c), statm) for c in fh.read().split())
        except (FileNotFoundError, ProcessLookupError, PermissionError):
            continue
    return total


def _statm(pid: int) -> str:
    with open(f"/proc/{pid}/statm") as fh:
        return fh.read()


def tree_rss_bytes(pid: int) -> int:
    """Resident memory of a process and all its descendants (Linux /proc)."""
    return tree_sum_bytes(pid, "status", "VmRSS:")


def timed_run(args: list[str]) -> tuple[float, int]:
    """Wall time [s] and peak tree RSS [bytes] of `vehid ARGS`."""
    peak = 0
    start = time.perf_counter()
    cmd = [sys.executable, "-m", "vehid_cli", *args]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    done = threading.Event()

    def sample() -> None:
        nonlocal peak
        while not done.is_set():
            peak = max(peak, tree_rss_bytes(proc.pid))
            time.sleep(0.05)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    code = proc.wait()
    done.set()
    sampler.join()
    if code != 0:
        sys.exit(f"vehid {' '.join(args)} exited {code}")
    return time.perf_counter() - start, peak


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--sweep", action="store_true", help="also time the Table 1 + 2 sweep (minutes)")
    args = parser.parse_args()
    print(f"# {platform.node()} {platform.machine()}, {os.cpu_count()} cores, python {platform.python_version()}")
    helps = []
    for _ in range(max(args.repeats, 5)):
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "vehid_cli", "--help"], cwd=ROOT, stdout=subprocess.DEVNULL, check=True)
        helps.append(time.perf_counter() - start)
    print(f"{'vehid --help':<40} median wall {statistics.median(helps):6.2f} s  (runs: "
          f"{', '.join(f'{w:.2f}' for w in helps)})")  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        hybrid = ["identify.algorithm.name=hybrid", "identify.objective=wls", "sensors=acc"]
        lsq = ["identify.algorithm.name=lsq", "identify.objective=wls"]
        bingham = ROOT / "configs" / "dampers" / "synthetic_bingham.yaml"
        for k, (name, config, extra) in enumerate(
            (
                ("lsq + wls, 30 runs", BASE, [x for s in lsq for x in ("--set", s)]),
                ("paper campaign: abc, f2, 30 x 1000", BASE, []),
                ("hybrid + wls, acc, 30 runs", BASE, [x for s in hybrid for x in ("--set", s)]),
                ("damper: bingham, 30 runs x 300", bingham, ["--runs", "30"]),
            )
        ):
            walls, peaks = [], []
            for i in range(args.repeats):
                wall, peak = timed_run(["identify", str(config), "-o", f"{tmp}/c{k}-{i}.h5", *extra])
                walls.append(wall)
                peaks.append(peak)
            print(f"{name:<40} median wall {statistics.median(walls):6.1f} s  (runs: "
                  f"{', '.join(f'{w:.1f}' for w in walls)})  peak RSS {max(peaks) / 2**20:6.0f} MiB")  # fmt: skip
        if args.sweep:
            varies = ["identify.objective=f1,f2", "noise.level=0.1,0.2", "identify.algorithm.name=ga,cpso,abc,hybrid"]
            sweep = ["sweep", str(BASE), "-o", f"{tmp}/sweep", *[x for v in varies for x in ("--vary", v)]]
            wall, peak = timed_run(sweep)
            print(f"{'Table 1 + 2 sweep (16 campaigns)':<40} wall {wall:6.1f} s  peak RSS {peak / 2**20:6.0f} MiB")


if __name__ == "__main__":
    main()
