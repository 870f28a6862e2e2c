"""Start-up of `vehid diagnose` (a benchmark, not a test): what a 3 s car diagnosis pays before and around its loop.

Each figure is a median over `--repeats` fresh processes, printed beside its anchor timed in the same run
(`vehid --help`, the start-up every command pays): (1) importing what a car's diagnosis imports (the CLI, the
systems' registry, the car's loop and its report), and how many vehid_cli modules that is, whether h5py is among
them; (2) the whole `vehid diagnose` of a 3 s bump run with 5 % noise and nothing missing (the case of issue 26's
"a 3 s diagnose <= 2 s"). `--against DIR` times the same on another source tree (e.g. an archive of an earlier
commit), its runs interleaved with this tree's, each process started in its own tree (`python -m` puts the working
directory first on the path), and prints the ratio of the medians.

`--pyc` first compiles both trees' modules to bytecode (`compileall`, as `pip install` does): with
PYTHONDONTWRITEBYTECODE set (as on the project's VM) Python otherwise compiles every vehid_cli module from source in
every process, which an installed package never does.
Run: python benchmarks/bench_startup.py [--repeats 7] [--against DIR] [--pyc]
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
BASE = Path("configs") / "gokdag2015" / "base.yaml"
IMPORTS = (
    "import sys, time; t = time.perf_counter(); import vehid_cli.cli.app, vehid_cli.systems, "
    "vehid_cli.systems.vehicle.diagnosis, vehid_cli.report.diagnosis; dt = time.perf_counter() - t; "
    "n = sum(m.startswith('vehid_cli') for m in sys.modules); print(dt, n, 'h5py' in sys.modules)"
)


def run(root: Path, *args: str) -> tuple[float, str]:
    """`python args` in a fresh process in the tree `root`: its wall time [s] and its stdout."""
    env = {**os.environ, "PYTHONPATH": str(root)}
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, *args], cwd=root, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    if proc.returncode:
        raise SystemExit(proc.stderr)
    return wall, proc.stdout


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--against", type=Path, help="another source tree, timed interleaved with this one")
    parser.add_argument("--pyc", action="store_true", help="compile both trees to bytecode first")
    args = parser.parse_args()
    trees = {"this tree": ROOT} | ({str(args.against): args.against.resolve()} if args.against else {})
    if args.pyc:
        for root in trees.values():
            subprocess.run([sys.executable, "-m", "compileall", "-q", str(root / "vehid_cli")], check=True)
    print(f"# {os.cpu_count()} cpus, load average {os.getloadavg()[0]:.1f}, bytecode "
          f"{'compiled first' if args.pyc else 'as the environment leaves it'}")  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "run.csv"
        run(ROOT, "-m", "vehid_cli", "simulate", str(BASE), "-o", str(data), "--set", "noise.level=0.05")
        help_s, imports, walls, shape = [], {k: [] for k in trees}, {k: [] for k in trees}, {}
        for _ in range(args.repeats):
            help_s.append(run(ROOT, "-m", "vehid_cli", "--help")[0])
            for name, root in trees.items():
                _, out = run(root, "-c", IMPORTS)
                dt, n, h5 = out.split()
                imports[name].append(float(dt))
                shape[name] = (n, h5)
                diag = (
                    "-m",
                    "vehid_cli",
                    "diagnose",
                    str(BASE),
                    "--data",
                    str(data),
                    "--json",
                    str(Path(tmp) / "d.json"),
                )
                walls[name].append(run(root, *diag)[0])
    anchor = statistics.median(help_s)
    print(f"anchor: vehid --help median {anchor:.2f} s wall")
    for name in trees:
        imp, wall = statistics.median(imports[name]), statistics.median(walls[name])
        n, h5 = shape[name]
        print(f"{name}: imports {imp:.2f} s ({n} vehid_cli modules, h5py loaded: {h5}); 3 s diagnose, nothing "
              f"missing: median {wall:.2f} s wall ({', '.join(f'{w:.2f}' for w in walls[name])}); "
              f"ratio to the anchor {wall / anchor:.1f}")  # fmt: skip
    if args.against:
        ours, theirs = "this tree", str(args.against)
        ratio_i = statistics.median(imports[ours]) / statistics.median(imports[theirs])
        ratio_w = statistics.median(walls[ours]) / statistics.median(walls[theirs])
        print(f"this tree / {theirs}: imports {ratio_i:.3f}, diagnose wall {ratio_w:.3f}")


if __name__ == "__main__":
    main()
