"""Start-up of `vehid diagnose` (a benchmark, not a test): what a 3 s car diagnosis pays before and around its loop.

Each figure is a median over `--repeats` fresh processes, printed beside its anchor timed in the same run
(`vehid --help`, the start-up every command pays): (1) importing what a car's diagnosis imports (the CLI, the
systems' registry, the car's loop and its report), and how many vehid_cli modules that is, whether h5py is among
them; (2) the whole `vehid diagnose` of a 3 s bump run with 5 % noise and nothing missing (the case of issue 26's
"a 3 s diagnose <= 2 s"; `--all`: also kf/cr mis-set and a Bouc-Wen hysteresis), wall and CPU time. `--against DIR`
times the same on another source tree (e.g. an archive of an earlier commit), its runs interleaved with this
tree's, each process started in its own tree (`python -m` puts the working
directory first on the path), and prints the ratio of the medians.

`--pyc` first compiles both trees' modules to bytecode (`compileall`, as `pip install` does): with
PYTHONDONTWRITEBYTECODE set (as on the project's VM) Python otherwise compiles every vehid_cli module from source in
every process, which an installed package never does.
Run: python benchmarks/bench_startup.py [--repeats 7] [--against DIR] [--pyc] [--all]
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
CASES = {  # name: (truth config, simulate --set overrides); each diagnosed with BASE, 5 % noise
    "3 s bump, nothing missing": (BASE, []),
    "3 s bump, kf +20 % and cr -15 %": (BASE, ["vehicle.kf=54000", "vehicle.cr=2975"]),
    "3 s bump, Bouc-Wen yielding at 13 mm": (
        Path("configs") / "effects" / "hysteresis.yaml",
        ["vehicle.effects.hysteresis.beta=3e3", "vehicle.effects.hysteresis.gamma=3e3"],
    ),
}
IMPORTS = (
    "import sys, time; t = time.perf_counter(); import vehid_cli.cli.app, vehid_cli.systems, "
    "vehid_cli.systems.vehicle.diagnosis, vehid_cli.report.diagnosis; dt = time.perf_counter() - t; "
    "n = sum(m.startswith('vehid_cli') for m in sys.modules); print(dt, n, 'h5py' in sys.modules)"
)


def run(root: Path, *args: str) -> tuple[float, str, float]:
    """`python args` in a fresh process in the tree `root`: its wall time [s], its stdout and its CPU time [s] (user
    + system, os.wait4: on a loaded machine the CPU a run needs moves less than its wall time)."""
    env = {**os.environ, "PYTHONPATH": str(root)}
    start = time.perf_counter()
    with tempfile.TemporaryFile("w+") as out:
        proc = subprocess.Popen([sys.executable, *args], cwd=root, env=env, stdout=out, stderr=subprocess.DEVNULL)
        _, status, usage = os.wait4(proc.pid, 0)
        wall = time.perf_counter() - start
        proc.returncode = os.waitstatus_to_exitcode(status)
        if proc.returncode:
            raise SystemExit(f"{args} failed in {root}")
        out.seek(0)
        return wall, out.read(), usage.ru_utime + usage.ru_stime


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--against", type=Path, help="another source tree, timed interleaved with this one")
    parser.add_argument("--pyc", action="store_true", help="compile both trees to bytecode first")
    parser.add_argument("--all", action="store_true", help="also the kf/cr and the hysteresis cases")
    args = parser.parse_args()
    trees = {"this tree": ROOT} | ({str(args.against): args.against.resolve()} if args.against else {})
    if args.pyc:
        for root in trees.values():
            subprocess.run([sys.executable, "-m", "compileall", "-q", str(root / "vehid_cli")], check=True)
    print(f"# {os.cpu_count()} cpus, load average {os.getloadavg()[0]:.1f}, bytecode "
          f"{'compiled first' if args.pyc else 'as the environment leaves it'}")  # fmt: skip
    cases = CASES if args.all else dict(list(CASES.items())[:1])
    help_s, imports, shape = [], {k: [] for k in trees}, {}
    walls = {(c, k): [] for c in cases for k in trees}
    cpus = {(c, k): [] for c in cases for k in trees}
    with tempfile.TemporaryDirectory() as tmp:
        data = {}
        for case, (truth, sets) in cases.items():
            data[case] = Path(tmp) / f"{len(data)}.csv"
            more = [a for v in ["noise.level=0.05", *sets] for a in ("--set", v)]
            run(ROOT, "-m", "vehid_cli", "simulate", str(truth), "-o", str(data[case]), *more)
        for _ in range(args.repeats):
            help_s.append(run(ROOT, "-m", "vehid_cli", "--help")[0])
            for name, root in trees.items():
                _, out, _ = run(root, "-c", IMPORTS)
                dt, n, h5 = out.split()
                imports[name].append(float(dt))
                shape[name] = (n, h5)
                for case in cases:
                    json_out = str(Path(tmp) / "d.json")
                    wall, _, cpu = run(root, "-m", "vehid_cli", "diagnose", str(BASE), "--data", str(data[case]),
                                       "--json", json_out)  # fmt: skip
                    walls[case, name].append(wall)
                    cpus[case, name].append(cpu)
    anchor = statistics.median(help_s)
    med = statistics.median
    print(f"anchor: vehid --help median {anchor:.2f} s wall")
    for name in trees:
        n, h5 = shape[name]
        print(f"{name}: imports {med(imports[name]):.2f} s ({n} vehid_cli modules, h5py loaded: {h5})")
        for case in cases:
            w, c = walls[case, name], cpus[case, name]
            print(f"    {case}: median {med(w):.2f} s wall ({', '.join(f'{x:.2f}' for x in w)}), {med(c):.2f} s "
                  f"CPU; ratio to the anchor {med(w) / anchor:.1f}")  # fmt: skip
    if args.against:
        ours, theirs = "this tree", str(args.against)
        print(f"this tree / {theirs}: imports {med(imports[ours]) / med(imports[theirs]):.3f}")
        for case in cases:
            ratio_w = med(walls[case, ours]) / med(walls[case, theirs])
            ratio_c = med(cpus[case, ours]) / med(cpus[case, theirs])
            print(f"    {case}: wall {ratio_w:.3f}, CPU {ratio_c:.3f}")


if __name__ == "__main__":
    main()
