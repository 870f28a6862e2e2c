"""Load: a sweep of many small campaigns over 2 workers, checked whole, with wall time and memory (issue 7).

Runs `vehid sweep` through the CLI (as a user runs it) over N campaigns (`--vary identify.seed=1..N`; each a
small campaign: 1.5 s of the paper's bump at 2 ms, 4 runs of DE with 8 x 5 evaluations), on the local
executor (`--jobs 2`) or on a two-worker Dask LocalCluster on the loopback interface (`--executor dask`). Then
checks that every planned campaign file is present, whole (checksum) and holds its planned config, that
`vehid report` reads them all, and that no lock, temporary or checkpoint file is left.

Memory: the resident memory of the whole process tree (the sweep and its workers; for Dask also the cluster's
worker processes) is sampled every 0.1 s; "bounded" means the peak over the last quarter of the campaigns is
no higher than over the first quarter plus 10 %. `getrusage(RUSAGE_CHILDREN).ru_maxrss` (the largest single
process) is reported as well.

Run: python benchmarks/bench_load.py [--campaigns 200] [--executor local|dask] [--json FILE]
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASE = ROOT / "configs" / "gokdag2015" / "base.yaml"
SMALL = [
    "simulation.duration=1.5", "simulation.dt=0.002", "identify.runs=4", "identify.algorithm.name=de",
    "identify.algorithm.population=8", "identify.algorithm.iterations=5",
]  # fmt: skip


def tree_rss_bytes(pid: int, include_self: bool = True) -> int:
    """Resident memory of a process and all its descendants (Linux /proc)."""
    total, stack, first = 0, [pid], True
    while stack:
        p = stack.pop()
        try:
            if include_self or not first:
                with open(f"/proc/{p}/status") as fh:
                    for line in fh:
                        if line.startswith("VmRSS:"):
                            total += int(line.split()[1]) * 1024
            first = False
            for task in os.listdir(f"/proc/{p}/task"):
                with open(f"/proc/{p}/task/{task}/children") as fh:
                    stack.extend(int(c) for c in fh.read().split())
        except (FileNotFoundError, ProcessLookupError, PermissionError):
            continue
    return total


def run_load(n: int, out_dir: Path, executor: str = "local", workers: int = 2) -> dict:
    """Run the sweep, sample memory and progress, verify the results; return the measurements."""
    seeds = ",".join(str(i) for i in range(1, n + 1))
    args = ["sweep", str(BASE), "--vary", f"identify.seed={seeds}", "-o", str(out_dir)]
    for s in SMALL:
        args += ["--set", s]
    cluster = None
    if executor == "dask":
        from distributed import LocalCluster

        cluster = LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
        )
        args += ["--executor", "dask", "--scheduler", cluster.scheduler_address]
    else:
        args += ["--jobs", str(workers)]
    samples: list[tuple[float, int, int]] = []  # (time, finished files, tree RSS)
    try:
        start = time.perf_counter()
        proc = subprocess.Popen(
            [sys.executable, "-m", "vehid_cli", *args], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE
        )
        done = threading.Event()

        def sample() -> None:
            while not done.is_set():
                # the sweep's tree, and for Dask the cluster's processes (children of this process) too
                rss = tree_rss_bytes(proc.pid) if cluster is None else tree_rss_bytes(os.getpid(), include_self=False)
                samples.append((time.perf_counter() - start, len(list(out_dir.glob("*.h5"))), rss))
                time.sleep(0.1)

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        stdout, stderr = proc.communicate()
        wall = time.perf_counter() - start
        done.set()
        sampler.join()
    finally:
        if cluster is not None:
            cluster.close()
    if proc.returncode != 0:
        raise SystemExit(f"sweep failed ({proc.returncode}):\n{stderr.decode()[-3000:]}")
    return dict(
        campaigns=n, executor=executor, workers=workers, wall_s=wall, **verify(out_dir, n), **memory(samples, n),
        largest_process_maxrss_mib=resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024,
    )  # fmt: skip


def verify(out_dir: Path, n: int) -> dict:
    """Every planned campaign file present, whole and holding its planned config; the report reads them all."""
    from vehid_cli.campaign.results import read_campaign_h5
    from vehid_cli.campaign.sweep import read_index

    index = read_index(out_dir / "index.csv")
    assert len(index) == n, f"index lists {len(index)} campaigns, expected {n}"
    for row in index:
        campaign = read_campaign_h5(out_dir / row["file"])  # raises for a missing or damaged file
        assert campaign.config.digest() == row["config_sha256"], row["file"]
        assert len(campaign.records) == 4, row["file"]
    report = subprocess.run(
        [sys.executable, "-m", "vehid_cli", "report", str(out_dir), "--format", "csv"],
        cwd=ROOT, capture_output=True, text=True, check=True,
    )  # fmt: skip
    rows = list(csv.DictReader(io.StringIO(report.stdout)))
    assert len(rows) == 5 * n, f"report has {len(rows)} rows, expected {5 * n}"
    leftovers = [p.name for p in out_dir.iterdir() if p.name.startswith(".") or p.name.endswith(".partial")]
    assert not leftovers, f"left behind: {leftovers}"
    return dict(files_verified=len(index), report_rows=len(rows))


def memory(samples: list[tuple[float, int, int]], n: int) -> dict:
    """Peak tree RSS overall, over the first and over the last quarter of the campaigns."""
    mib = 1024 * 1024
    first = [r for _, k, r in samples if k <= n // 4] or [0]
    last = [r for _, k, r in samples if k >= n - n // 4] or [0]
    peak = max((r for _, _, r in samples), default=0)
    return dict(
        peak_tree_rss_mib=peak / mib, first_quarter_peak_mib=max(first) / mib, last_quarter_peak_mib=max(last) / mib,
        memory_bounded=max(last) <= 1.10 * max(first), samples=len(samples),
    )  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--campaigns", type=int, default=200)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--executor", choices=("local", "dask"), default="local")
    parser.add_argument("--json", type=Path, help="also write the measurements here")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="vehid-load-") as tmp:
        result = run_load(args.campaigns, Path(tmp) / "sweep", args.executor, args.workers)
    result.update(
        host=platform.node(), machine=platform.machine(), cpus=os.cpu_count(), python=platform.python_version()
    )
    print(f"# {result['host']} {result['machine']}, {result['cpus']} cpus, python {result['python']}")
    print(
        f"{args.campaigns} campaigns x 4 runs, {args.executor} executor, {args.workers} workers: "
        f"wall {result['wall_s']:.1f} s ({result['wall_s'] / args.campaigns:.2f} s/campaign); "
        f"{result['files_verified']} files verified, report {result['report_rows']} rows; "
        f"peak tree RSS {result['peak_tree_rss_mib']:.0f} MiB (first quarter {result['first_quarter_peak_mib']:.0f}, "
        f"last quarter {result['last_quarter_peak_mib']:.0f}: bounded {result['memory_bounded']}); "
        f"largest process {result['largest_process_maxrss_mib']:.0f} MiB"
    )
    if args.json:
        args.json.write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
