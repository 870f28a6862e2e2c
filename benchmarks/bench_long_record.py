"""A long logger record identified to the bound (issues 13 and 26): a 60 s four-post rig run at 1 kHz (60 000 samples
x 16 channels plus the 4 actuators, MDF4 with 200 Hz potentiometers, g and mm, offsets) identified with `lsq`
through the CLI, as a user runs it. Targets (issue 26): <= 5 s wall on 2 cores, peak memory of the process tree
<= 300 MiB, and the estimate within the bound (its z-scores printed). A benchmark, not a test. The tree's memory is
given as summed RSS (the issue's measure) and as PSS (pages shared between processes counted once): the logger file
is read in a child process (core/isolated.py: a fresh interpreter; a forked one, before, counted its parent's pages
a second time).

Each figure is printed beside anchors measured in the same run, interleaved repeat by repeat (a loaded machine
slows them alike), after one untimed run of each: the same command on a short record (`--anchor`, 3 s), and with
`--against DIR` the same long record identified by another checkout of vehid (e.g. the commit before a change:
`git archive COMMIT | tar -x -C DIR`).

Run: python benchmarks/bench_long_record.py [--repeats 3] [--duration 60] [--anchor 3] [--against DIR]
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
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.bench_campaign import tree_rss_bytes, tree_sum_bytes  # noqa: E402
from benchmarks.machine import host  # noqa: E402
from examples.make_rig_runs import write_rig_run  # noqa: E402
from vehid_cli.config import load_config  # noqa: E402
from vehid_cli.systems import build_system  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RIG = Path("configs") / "examples" / "four_post_rig.yaml"


def tree_pss_bytes(pid: int) -> int:
    """Proportional set size of a process and its descendants (Linux /proc/PID/smaps_rollup): pages shared by a
    forked child and its parent (the logger file's reader runs in one, core/isolated.py) counted once, where the
    summed RSS counts them in both."""
    return tree_sum_bytes(pid, "smaps_rollup", "Pss:")


def identify(tree: Path, run: Path, duration: float, out: Path) -> tuple[float, int, int]:
    """Wall time [s], peak tree RSS and peak tree PSS [bytes] of `vehid identify` of the rig on `run` by the vehid
    in `tree`."""
    sets = [f"simulation.duration={duration:g}", "identify.truth=config"]
    cmd = [sys.executable, "-m", "vehid_cli", "identify", str(tree / RIG), "--data", str(run), "-o", str(out)]
    cmd += ["--json", str(out.with_suffix(".json")), *sum((["--set", s] for s in sets), [])]
    env = dict(os.environ, PYTHONPATH=str(tree))
    peak = pss = 0
    start = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=tree, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    done = threading.Event()

    def sample() -> None:
        nonlocal peak, pss
        while not done.is_set():
            peak = max(peak, tree_rss_bytes(proc.pid))
            pss = max(pss, tree_pss_bytes(proc.pid))
            time.sleep(0.05)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    _, err = proc.communicate()
    done.set()
    sampler.join()
    if proc.returncode != 0:
        sys.exit(f"{' '.join(cmd)} exited {proc.returncode}: {err.decode()[-2000:]}")
    return time.perf_counter() - start, peak, pss


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--duration", type=float, default=60.0)
    parser.add_argument("--anchor", type=float, default=3.0, help="duration [s] of the anchor's short record")
    parser.add_argument("--against", type=Path, help="another vehid checkout to identify the long record with")
    args = parser.parse_args()
    print(f"# {host()}, {os.cpu_count()} cores, python {platform.python_version()}")
    cases = {
        f"identify lsq, {args.anchor:g} s record (anchor)": (ROOT, args.anchor),
        f"identify lsq, {args.duration:g} s record": (ROOT, args.duration),
    }
    if args.against is not None:
        cases[f"  the same by {args.against}"] = (args.against.resolve(), args.duration)
    with tempfile.TemporaryDirectory() as tmp:
        runs = {d: write_rig_run(ROOT / RIG, Path(tmp) / f"rig{d:g}.mf4", 5, [f"simulation.duration={d:g}"])
                for d in {args.anchor, args.duration}}  # fmt: skip
        long_run = runs[args.duration]
        print(f"{long_run.name}: {long_run.stat().st_size / 1e6:.1f} MB, {args.duration:g} s at 1 kHz")
        walls: dict[str, list[float]] = {k: [] for k in cases}
        peaks: dict[str, list[int]] = {k: [] for k in cases}
        shares: dict[str, list[int]] = {k: [] for k in cases}
        for i, (tree, duration) in enumerate(cases.values()):  # untimed: numba's caches filled, files in the page cache
            identify(tree, runs[duration], duration, Path(tmp) / f"warm{i}.h5")
        for k in range(args.repeats):  # interleaved: each repeat runs every case once
            for i, (label, (tree, duration)) in enumerate(cases.items()):
                out = Path(tmp) / f"fit{k}-{i}.h5"
                wall, peak, pss = identify(tree, runs[duration], duration, out)
                walls[label].append(wall)
                peaks[label].append(peak)
                shares[label].append(pss)
                if tree == ROOT and duration == args.duration:
                    doc = json.loads(out.with_suffix(".json").read_text())
        system = build_system(load_config(ROOT / RIG, [f"simulation.duration={args.duration:g}",
                                                       "identify.truth=config"]), long_run)  # fmt: skip
        bound = system.bound()
        estimate = np.array([doc["mean"][n] for n in doc["parameters"]])
        z = (estimate - system.box.truth) / bound.sd
    anchor = next(iter(cases))
    for label in cases:
        wall, peak, pss = statistics.median(walls[label]), max(peaks[label]) / 2**20, max(shares[label]) / 2**20
        runs_s = ", ".join(f"{w:.2f}" for w in walls[label])
        ratio = "" if label == anchor else f"  ({wall / statistics.median(walls[anchor]):.2f} x the anchor's wall)"
        print(f"{label:<44} median wall {wall:6.2f} s (runs: {runs_s}); peak tree RSS {peak:.0f} MiB, "
              f"PSS {pss:.0f} MiB{ratio}")  # fmt: skip
    scores = " ".join(f"{n} {v:+.2f}" for n, v in zip(doc["parameters"], z, strict=True))
    print(f"{'z-scores (estimate - truth) / CRLB sd':<44} {scores}")
    print(f"{'evaluations':<44} {doc['evaluations_per_run']}, CRLB NRE {bound.nre_rms_percent:.4f} %")


if __name__ == "__main__":
    main()
