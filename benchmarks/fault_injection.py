"""Fault injection (issue 7): interrupt campaigns and sweeps at random moments, damage result files at random
bytes, and check that nothing is lost and nothing is silently wrong. A reliability check, not a speed benchmark.

Trials (each with its own random draw from `--seed`):
- `identify`: a 12-run campaign on 2 worker processes gets SIGKILL, SIGTERM or SIGINT (to its process group, as
  Ctrl-C) after a random delay between its start and its expected end (the final write included); then the same
  command is run again. Pass: the resumed file has exactly the datasets of an uninterrupted campaign, no temporary,
  lock or checkpoint file is left, no worker process outlives the killed one.
- `sweep`: the same for a 6-campaign sweep (`--jobs 2`), compared file by file with an uninterrupted sweep.
- `damage`: a finished campaign file gets one random byte flipped, or is cut at a random length. Pass: reading it
  either fails with a message naming it (exit 2 from `vehid report`), or gives exactly the original content
  (a flipped byte in unused space changes nothing).

Run: python benchmarks/fault_injection.py [--identify 30] [--sweep 10] [--damage 200] [--seed 1] [--json FILE]
"""

from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import h5py
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
BASE = ROOT / "configs" / "gokdag2015" / "base.yaml"
SMALL = [
    "simulation.duration=1.5", "simulation.dt=0.002", "identify.algorithm.name=de",
    "identify.algorithm.population=8", "identify.algorithm.iterations=30",
]  # fmt: skip
SIGNALS = (signal.SIGKILL, signal.SIGTERM, signal.SIGINT)


def sets(items: list[str]) -> list[str]:
    return [x for s in items for x in ("--set", s)]


def identify_cmd(target: Path, jobs: int = 2) -> list[str]:
    return ["identify", str(BASE), *sets(SMALL + ["identify.runs=12"]), "--jobs", str(jobs), "-o", str(target)]


def sweep_cmd(out_dir: Path) -> list[str]:
    vary = ["--vary", "identify.algorithm.name=de,cpso,abc", "--vary", "noise.level=0.1,0.2"]
    return ["sweep", str(BASE), *vary, *sets(SMALL + ["identify.runs=4"]), "--jobs", "2", "-o", str(out_dir)]


def vehid(args: list[str], **kw) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "vehid_cli", *args], cwd=ROOT, capture_output=True, text=True, **kw)


def content(path: Path) -> dict:
    """Every dataset of a campaign file, and its config (provenance such as times excluded); wall times dropped."""
    out = {}
    with h5py.File(path) as h5:
        h5.visititems(lambda name, obj: out.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
        out["config_yaml"] = h5.attrs["config_yaml"]
    out.pop("runs/wall_s", None)
    return out


def same(a: dict, b: dict) -> bool:
    def equal(x, y) -> bool:
        x, y = np.asarray(x), np.asarray(y)
        return np.array_equal(x, y, equal_nan=x.dtype.kind == "f" and y.dtype.kind == "f")

    return a.keys() == b.keys() and all(equal(a[k], b[k]) for k in a)


def descendants(pid: int) -> list[int]:
    out, stack = [], [pid]
    while stack:
        p = stack.pop()
        try:
            for task in os.listdir(f"/proc/{p}/task"):
                with open(f"/proc/{p}/task/{task}/children") as fh:
                    kids = [int(c) for c in fh.read().split()]
                out += kids
                stack += kids
        except (FileNotFoundError, ProcessLookupError):
            continue
    return out


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def interrupt(args: list[str], delay: float, sig: signal.Signals) -> dict:
    """Start `vehid ARGS`, send `sig` after `delay` s (unless it finished), wait; what happened."""
    env = dict(os.environ, PYTHONFAULTHANDLER="1")  # a hung process dumps its threads' stacks on SIGABRT
    proc = subprocess.Popen(
        [sys.executable, "-m", "vehid_cli", *args], cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
        text=True, start_new_session=True, env=env,
    )  # fmt: skip
    deadline = time.perf_counter() + delay
    workers: set[int] = set()
    while time.perf_counter() < deadline and proc.poll() is None:
        workers.update(descendants(proc.pid))
        time.sleep(0.02)
    sent = proc.poll() is None
    if sent:
        workers.update(descendants(proc.pid))
        (os.killpg if sig == signal.SIGINT else os.kill)(proc.pid, sig)
    hung = []
    try:
        _, stderr = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:  # something still holds its stderr: say what, with its stacks, then end it
        hung = [(p, open(f"/proc/{p}/cmdline").read().replace("\0", " ")[:200]) for p in session(proc.pid)]
        for p, _ in hung:
            os.kill(p, signal.SIGABRT)
        time.sleep(2)
        for p in session(proc.pid):
            os.kill(p, signal.SIGKILL)
        _, stderr = proc.communicate(timeout=60)
    time.sleep(1.5)  # workers of a SIGKILLed parent notice within 0.5 s
    return dict(
        sent=sent, returncode=proc.returncode, traceback="Traceback" in stderr and not hung,
        orphans=sum(alive(w) for w in workers), hung=hung,
        stderr_tail=stderr[-4000:] if hung or "Traceback" in stderr else "",  # what to read when a trial fails
    )  # fmt: skip


def session(sid: int) -> list[int]:
    """Live processes of session `sid` (the interrupted command started one)."""
    out = []
    for name in os.listdir("/proc"):
        if name.isdigit():
            try:
                with open(f"/proc/{name}/stat") as fh:
                    fields = fh.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[3]) == sid and fields[0] != "Z":
                out.append(int(name))
    return out


def leftovers(directory: Path) -> list[str]:
    return [p.name for p in directory.iterdir() if p.name.startswith(".") or p.name.endswith(".partial")]


def identify_trials(n: int, rng: random.Random, work: Path) -> list[dict]:
    ref = work / "whole.h5"
    start = time.perf_counter()
    assert vehid(identify_cmd(ref)).returncode == 0
    span = time.perf_counter() - start
    expected = content(ref)
    trials = []
    for i in range(n):
        target = work / f"t{i}.h5"
        sig, delay = rng.choice(SIGNALS), rng.uniform(0.2, span)
        hit = interrupt(identify_cmd(target), delay, sig)
        partial = Path(str(target) + ".partial")
        saved = len(list(partial.glob("run-*.npz"))) if partial.exists() else (12 if target.exists() else 0)
        again = vehid(identify_cmd(target, jobs=rng.choice((1, 2))))
        ok = again.returncode == 0 and same(content(target), expected) and not leftovers(work)
        ok = ok and not hit["traceback"] and hit["orphans"] == 0 and not hit["hung"]
        trials.append(dict(kind="identify", signal=sig.name, delay_s=round(delay, 2), runs_saved=saved, ok=ok, **hit))
        target.unlink()
    return trials


def sweep_trials(n: int, rng: random.Random, work: Path) -> list[dict]:
    ref = work / "whole"
    start = time.perf_counter()
    assert vehid(sweep_cmd(ref)).returncode == 0
    span = time.perf_counter() - start
    expected = {p.name: content(p) for p in ref.glob("*.h5")}
    trials = []
    for i in range(n):
        out_dir = work / f"s{i}"
        sig, delay = rng.choice(SIGNALS), rng.uniform(0.2, span)
        hit = interrupt(sweep_cmd(out_dir), delay, sig)
        finished = len(list(out_dir.glob("*.h5"))) if out_dir.exists() else 0
        again = vehid(sweep_cmd(out_dir))
        got = {p.name: content(p) for p in out_dir.glob("*.h5")}
        why = {  # what a failed trial got wrong
            "rerun_returncode": again.returncode, "rerun_stderr_tail": again.stderr[-2000:] if again.returncode else "",
            "missing": sorted(expected.keys() - got.keys()), "extra": sorted(got.keys() - expected.keys()),
            "differ": sorted(k for k in got.keys() & expected.keys() if not same(got[k], expected[k])),
            "leftovers": leftovers(out_dir),
        }  # fmt: skip
        ok = again.returncode == 0 and not (why["missing"] or why["extra"] or why["differ"] or why["leftovers"])
        ok = ok and not hit["traceback"] and hit["orphans"] == 0 and not hit["hung"]
        trials.append(
            dict(kind="sweep", signal=sig.name, delay_s=round(delay, 2), campaigns_done=finished, ok=ok, **hit, **why)
        )
        shutil.rmtree(out_dir)
    return trials


def damage_trials(n: int, rng: random.Random, work: Path) -> list[dict]:
    sys.path.insert(0, str(ROOT))
    from vehid_cli.campaign.results import read_campaign_h5
    from vehid_cli.core.errors import InputError

    ref = work / "whole.h5"
    if not ref.exists():
        assert vehid(identify_cmd(ref)).returncode == 0
    original, data = content(ref), ref.read_bytes()
    trials = []
    for i in range(n):
        bad = work / f"d{i}.h5"
        blob = bytearray(data)
        if rng.random() < 0.5:
            kind, at = "flip", rng.randrange(len(blob))
            blob[at] ^= 1 << rng.randrange(8)
        else:
            kind, at = "truncate", rng.randrange(len(blob))
            blob = blob[:at]
        bad.write_bytes(bytes(blob))
        try:
            read_campaign_h5(bad)
            outcome = "read, unchanged" if same(content(bad), original) else "READ, CHANGED"
        except InputError:
            outcome = "refused"
        except Exception as exc:  # noqa: BLE001 - anything else is a finding
            outcome = f"CRASH {exc.__class__.__name__}"
        trials.append(
            dict(kind="damage", damage=kind, at=at, outcome=outcome, ok=outcome in ("refused", "read, unchanged"))
        )
        bad.unlink()
    return trials


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--identify", type=int, default=30)
    parser.add_argument("--sweep", type=int, default=10)
    parser.add_argument("--damage", type=int, default=200)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    rng = random.Random(args.seed)
    with tempfile.TemporaryDirectory(prefix="vehid-faults-") as tmp:
        work = Path(tmp)
        trials = identify_trials(args.identify, rng, work)
        trials += sweep_trials(args.sweep, rng, work)
        trials += damage_trials(args.damage, rng, work)
    for kind in ("identify", "sweep"):
        mine = [t for t in trials if t["kind"] == kind]
        if mine:
            by_signal = Counter(t["signal"] for t in mine if t["sent"])
            print(
                f"{kind}: {len(mine)} trials, {sum(t['sent'] for t in mine)} interrupted ({dict(by_signal)}), "
                f"{len(mine) - sum(t['sent'] for t in mine)} finished first; passed {sum(t['ok'] for t in mine)}/"
                f"{len(mine)}; tracebacks {sum(t['traceback'] for t in mine)}, orphan workers "
                f"{sum(t['orphans'] for t in mine)}, hung {sum(bool(t['hung']) for t in mine)}"
            )
    damage = [t for t in trials if t["kind"] == "damage"]
    if damage:
        print(f"damage: {len(damage)} trials, outcomes {dict(Counter((t['damage'], t['outcome']) for t in damage))}; "
              f"passed {sum(t['ok'] for t in damage)}/{len(damage)}")  # fmt: skip
    for t in trials:
        if not t["ok"]:
            print("FAILED:", t)
    if args.json:
        args.json.write_text(json.dumps(trials, indent=1))
    if not all(t["ok"] for t in trials):
        sys.exit(1)


if __name__ == "__main__":
    main()
