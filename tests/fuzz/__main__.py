"""The large fuzz campaign: every case in a child process as a user runs it, a table of what happened per family.

python -m tests.fuzz --cases 3000 --seed 1 --jobs 2 [--families yaml,mdf4] [--timeout 60] [--keep DIR]
Exit status 1 when any case had a problem (listed with its folder, kept under --keep).
"""

from __future__ import annotations

import argparse
import shutil
import tempfile
import time
from collections import Counter, defaultdict
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from . import baseline, load_families, make_case, plan, run_in_subprocess


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--cases", type=int, default=300)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--families", default="", help="comma-separated names (default: all)")
    parser.add_argument("--timeout", type=float, default=60.0)
    parser.add_argument("--keep", type=Path, default=None, help="keep the folders of cases with a problem here")
    args = parser.parse_args()
    families = load_families()
    names = [n for n in args.families.split(",") if n] or sorted(families)
    if not names:
        parser.error("no fuzz family is registered (tests/fuzz/<module>.py with @family)")
    unknown = sorted(set(names) - set(families))
    if unknown:
        parser.error(f"unknown families {unknown}; known: {', '.join(sorted(families))}")
    baseline()  # built in this process, before the threads share it
    todo = plan(args.seed, args.cases, names)
    work = Path(tempfile.mkdtemp(prefix="vehid-fuzz-run-"))
    t0 = time.perf_counter()

    def one(item):
        name, index = item
        folder = work / f"{name}-{index:05d}"
        try:
            case = make_case(name, args.seed, index, folder)
        except Exception as exc:  # noqa: BLE001 - a generator's own failure is the harness's, reported as such
            return name, index, None, f"generator failed: {exc!r}"
        outcome = run_in_subprocess(case, folder, args.timeout)
        if outcome.problems and args.keep:
            shutil.copytree(folder, args.keep / folder.name, symlinks=True, dirs_exist_ok=True)
        shutil.rmtree(folder, ignore_errors=True)
        return name, index, outcome, None

    table: dict[str, Counter] = defaultdict(Counter)
    bad = []
    with ThreadPoolExecutor(args.jobs) as pool:
        for name, index, outcome, failure in pool.map(one, todo):
            row = table[name]
            row["cases"] += 1
            if failure:
                row["harness"] += 1
                bad.append(f"{name}-{index:05d}: {failure}")
                continue
            row[f"exit {outcome.code}" if outcome.code is not None else "no exit"] += 1
            row["slowest"] = max(row["slowest"], round(outcome.seconds))
            if outcome.problems:
                row["problems"] += 1
                last = (outcome.text.strip().splitlines() or [""])[-1][:200]
                bad.append(f"{name}-{index:05d}: {'; '.join(outcome.problems)} | {outcome.case.what} | {last}")
    shutil.rmtree(work, ignore_errors=True)
    cols = ["cases", "exit 0", "exit 2", "exit 1", "no exit", "problems", "harness", "slowest"]
    print(f"# fuzz: {args.cases} cases, seed {args.seed}, {args.jobs} jobs, {time.perf_counter() - t0:.0f} s")
    print(f"{'family':<16}" + "".join(f"{c:>10}" for c in cols))
    for name in sorted(table):
        print(f"{name:<16}" + "".join(f"{table[name][c]:>10}" for c in cols))
    total = sum(table.values(), Counter())
    total["slowest"] = max(r["slowest"] for r in table.values())
    print(f"{'all':<16}" + "".join(f"{total[c]:>10}" for c in cols))
    for line in bad:
        print(line)
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
