"""Wall time of `vehid diagnose` as a user runs it (a benchmark, not a test).

Targets (issue 26): a 3 s car case in <= 2 s wall on 2 cores; a 60 s ISO-road record at 1 kHz in <= 15 s and
<= 300 MiB peak RSS (`--long`: an effect, two mis-set known parameters, a sensor upside down, nothing missing);
data too short to tell answered before any candidate is fitted. Each figure is printed beside an anchor timed in
the same run (`vehid --help`, the start-up every command pays), so a loaded machine can be read as a ratio.
Each case is simulated once by `vehid simulate` (the project's own simulator) and then diagnosed through the CLI
in a fresh process (imports and the cached kernels included), `--repeats` times; the median wall and the peak RSS
are reported. `--against DIR` also times each case on the source tree DIR (e.g. an archive of an earlier commit),
its runs interleaved with this tree's, and prints the ratio of the medians (this tree over DIR).
Run: python benchmarks/bench_diagnose.py [--repeats 3] [--long] [--against DIR]
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

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.bench_campaign import tree_rss_bytes  # noqa: E402
from benchmarks.machine import host  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
BASE = ROOT / "configs" / "gokdag2015" / "base.yaml"
HYSTERESIS = ROOT / "configs" / "effects" / "hysteresis.yaml"
CASES = {  # name: (truth config, simulate --set overrides, diagnose --set overrides)
    "3 s bump, kf +20 % and cr -15 % (two known parameters)": (
        BASE, ["vehicle.kf=54000", "vehicle.cr=2975"], []),
    "3 s bump, Bouc-Wen yielding at 13 mm": (
        HYSTERESIS, ["vehicle.effects.hysteresis.beta=3e3", "vehicle.effects.hysteresis.gamma=3e3"], []),
    "3 s bump, nothing missing": (BASE, [], []),
    "0.3 s bump (too short: refused before any candidate is fitted)": (
        BASE, ["simulation.duration=0.3"], ["simulation.duration=0.3"]),
}  # fmt: skip
ROAD60 = ["road.bump=null", "road.random.iso_class=C", "simulation.duration=60"]
LONG = {
    "60 s ISO class C road at 1 kHz, hysteresis": (HYSTERESIS, ROAD60, ROAD60),
    "60 s ISO class C road at 1 kHz, kf +20 % and cr -15 %": (BASE, [*ROAD60, "vehicle.kf=54000", "vehicle.cr=2975"],
                                                             ROAD60),
    "60 s ISO class C road at 1 kHz, acc2 upside down": (BASE, ROAD60, ROAD60),
    "60 s ISO class C road at 1 kHz, nothing missing": (BASE, ROAD60, ROAD60),
}  # fmt: skip
FLIPPED = {"60 s ISO class C road at 1 kHz, acc2 upside down": "acc2"}  # case: the channel whose sign is inverted


def vehid(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "vehid_cli", *args], cwd=ROOT, capture_output=True, text=True)


def timed(*args: str, root: Path = ROOT) -> tuple[float, float, int, float]:
    """`vehid args` in a fresh process (the package of the source tree `root`): its wall time [s], its peak RSS [MiB],
    its exit code and its peak anonymous memory [MiB]. The peak is the larger of the process's own high-water mark
    (VmHWM, read every 20 ms until it exits: it only grows) and the summed RSS of its process tree sampled as often (a
    logger file's reader runs in a child process). Not os.wait4's ru_maxrss: Linux folds into it the memory of the
    process that started the child, up to its exec (this benchmark's own, 320 MiB once `time_unexplained` has run in
    it, which every case then reported as its floor). The anonymous peak (RssAnon, sampled) leaves out the mapped
    files: their resident share depends on the page cache's state, not on the program (libllvmlite.so's pages, 94 MiB
    resident after a fresh `pip install` wrote them to the cache in large folios, 36 MiB once read back from disk)."""
    start = time.perf_counter()
    env = {**os.environ, "PYTHONPATH": str(root)}
    proc = subprocess.Popen([sys.executable, "-m", "vehid_cli", *args], cwd=root, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, env=env)  # fmt: skip
    peak = anon = 0
    while proc.poll() is None:
        try:
            with open(f"/proc/{proc.pid}/status") as fh:
                fields = {line.split(":")[0]: line for line in fh}
            own = int(fields["VmHWM"].split()[1]) * 1024 if "VmHWM" in fields else 0
            anon = max(anon, int(fields["RssAnon"].split()[1]) * 1024 if "RssAnon" in fields else 0)
        except OSError:
            own = 0
        peak = max(peak, own, tree_rss_bytes(proc.pid))
        time.sleep(0.02)
    return time.perf_counter() - start, peak / 2**20, proc.returncode, anon / 2**20


def anchor(repeats: int) -> float:
    """The anchor every figure is printed beside: `vehid --help` (interpreter and CLI start-up), median wall [s]."""
    return statistics.median(timed("--help")[0] for _ in range(max(repeats, 5)))


def sets(values: list[str]) -> list[str]:
    return [a for v in values for a in ("--set", v)]


def flip(path: Path, column: str) -> None:
    """The simulated CSV with `column`'s sign inverted (a sensor mounted upside down), its comments kept."""
    lines = path.read_text().splitlines()
    first = next(i for i, line in enumerate(lines) if not line.startswith("#"))
    j = lines[first].split(",").index(column)
    rows = [line.split(",") for line in lines[first + 1 :]]
    for row in rows:
        row[j] = repr(-float(row[j]))
    path.write_text("\n".join(lines[: first + 1] + [",".join(r) for r in rows]) + "\n")


def time_unexplained(repeats: int) -> None:
    """The missing-force estimate alone (diagnose/unexplained.py), in process: 3 s at 1 kHz, 24 000 residuals, 15 %
    more front damping in the data than in the model (target 1 s; it was an assertion in the test suite until
    load on the machine made it fail there: timing belongs here)."""
    import dataclasses

    from vehid_cli.config import load_config
    from vehid_cli.diagnose.unexplained import estimate_unexplained
    from vehid_cli.identify.task import build_task

    noise = ["identify.objective=wls", "noise.level=0.03", "identify.truth=config"]
    truth = build_task(load_config(BASE, [*noise, "vehicle.cf=3220"]))
    task = dataclasses.replace(build_task(load_config(BASE, noise)), sigma=truth.sigma)
    ref = truth.reference(0)
    estimate_unexplained(task, ref, task.names, task.nominal)  # compile and warm up
    walls = []
    for _ in range(max(repeats, 5)):
        start = time.perf_counter()
        estimate_unexplained(task, ref, task.names, task.nominal)
        walls.append(time.perf_counter() - start)
    runs = ", ".join(f"{w:.2f}" for w in walls)
    print(f"unexplained-force estimate, 3 s at 1 kHz: median {statistics.median(walls):.2f} s ({runs})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--long", action="store_true", help="also the 60 s record")
    parser.add_argument("--against", type=Path, help="another source tree, timed interleaved with this one")
    args = parser.parse_args()
    print(f"# {host()}, {os.cpu_count()} cpus, python {platform.python_version()}, "
          f"load average {os.getloadavg()[0]:.1f}")  # fmt: skip
    print(f"anchor: vehid --help median {anchor(args.repeats):.2f} s wall")
    time_unexplained(args.repeats)
    cases = {**CASES, **(LONG if args.long else {})}
    with tempfile.TemporaryDirectory() as tmp:
        for name, (truth, sim_sets, diag_sets) in cases.items():
            data, out = Path(tmp) / "run.csv", Path(tmp) / "diag.json"
            res = vehid("simulate", str(truth), "-o", str(data), "--set", "noise.level=0.05", *sets(sim_sets))
            if res.returncode:
                raise SystemExit(res.stderr)
            if name in FLIPPED:
                flip(data, FLIPPED[name])
            walls, peaks, anons, anchors, others, other_peaks = [], [], [], [], [], []
            command = ("diagnose", str(BASE), "--data", str(data), "--json", str(out), *sets(diag_sets))
            for _ in range(args.repeats):  # the anchor timed beside each run: the machine's load moves both
                anchors.append(anchor(1))
                if args.against is not None:
                    other = timed(*command, root=args.against.resolve())
                    others.append(other[0])
                    other_peaks.append(other[1])
                wall, peak, code, anon = timed(*command)
                if code:
                    raise SystemExit(vehid("diagnose", str(BASE), "--data", str(data), *sets(diag_sets)).stderr)
                walls.append(wall)
                peaks.append(peak)
                anons.append(anon)
            doc = json.loads(out.read_text())
            runs = ", ".join(f"{w:.1f}" for w in walls)
            wall, help_s = statistics.median(walls), statistics.median(anchors)
            print(f"{name}: median {wall:.1f} s wall ({runs}), peak RSS {max(peaks):.0f} MiB (anonymous "
                  f"{max(anons):.0f} MiB); anchor vehid --help "
                  f"{help_s:.2f} s (ratio {wall / help_s:.0f}); selected {doc['selected']}; "
                  f"verdict: {doc['verdict'][:60]}")  # fmt: skip
            if others:
                runs = ", ".join(f"{w:.1f}" for w in others)
                other = statistics.median(others)
                print(f"    {args.against}: median {other:.1f} s wall ({runs}), peak RSS {max(other_peaks):.0f} MiB; "
                      f"this tree / that {wall / other:.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
