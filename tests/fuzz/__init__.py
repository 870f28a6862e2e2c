"""Damaged and hostile input thrown at the command line (issue 22): the harness every input family shares.

A family is one module of this package holding generators registered with `@family("name")`: each takes a
`numpy.random.Generator` and a fresh working folder, writes its damaged files there (from the valid ones
`Baseline` builds once) and returns the `Case`: the `vehid` arguments to run, with a line saying what was done.
`run_case` runs it (in this process, or in a child process so that a crash or a hang is seen for what it is)
and `problems` says what went wrong: an exit status other than 0 or 2, a traceback, an "internal error", a
printed warning, a hang, a crash, or files left behind. Every case draws from its own stream
(`SeedSequence(seed).spawn`), so a campaign of cases is the same whatever order or process runs it.

Rerun the large campaign with `python -m tests.fuzz --cases 3000 --seed 1 --jobs 2` (see docs/reliability.md).
"""

from __future__ import annotations

import importlib
import os
import pkgutil
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
LEFTOVER = (".partial", ".lock", ".tmp")  # what a failed or finished command must not leave behind (name parts)
MARKERS = ("Traceback", "internal error", "Warning:", "Exception ignored")


@dataclass(frozen=True)
class Case:
    """One hostile input: the `vehid` arguments (paths inside the case's folder) and what was done to it."""

    family: str
    what: str
    args: tuple[str, ...]
    env: tuple[tuple[str, str], ...] = ()  # extra environment for the command (e.g. a tiny resource limit)


@dataclass(frozen=True)
class Outcome:
    """What a case did: exit status (None: it hung), the signal that ended it (crash), its text, new files."""

    case: Case
    code: int | None
    signal: int | None
    text: str
    leftovers: tuple[str, ...]
    seconds: float

    @property
    def problems(self) -> list[str]:
        """Everything the issue forbids, in words ('' list: a clean exit 0 or 2)."""
        found = []
        if self.code is None and self.signal is None:
            found.append("hang")
        elif self.signal is not None:
            found.append(f"crash (signal {self.signal})")
        elif self.code not in (0, 2):
            found.append(f"exit {self.code}")
        found += [f"printed {m!r}" for m in MARKERS if m in self.text]
        if self.leftovers:
            found.append(f"left {', '.join(self.leftovers)}")
        return found


Generator = Callable[[np.random.Generator, Path], Case]
FAMILIES: dict[str, Generator] = {}


def family(name: str) -> Callable[[Generator], Generator]:
    """Register a generator of hostile cases under `name` (unique)."""

    def register(fn: Generator) -> Generator:
        if name in FAMILIES:
            raise ValueError(f"fuzz family {name!r} registered twice")
        FAMILIES[name] = fn
        return fn

    return register


def load_families() -> dict[str, Generator]:
    """Import every module of this package, so that each registers its families."""
    for info in pkgutil.iter_modules(__path__):
        if not info.name.startswith("_"):
            importlib.import_module(f"{__name__}.{info.name}")
    return FAMILIES


# ------------------------------------------------------------------------------------------ valid inputs


class Baseline:
    """Valid inputs built once per folder (a cache the families mutate copies of): `get(name, build)` runs
    `build(path)` the first time `name` is asked for and returns the path afterwards."""

    def __init__(self, root: Path):
        self.root = Path(root)
        self.root.mkdir(parents=True, exist_ok=True)

    def get(self, name: str, build: Callable[[Path], None]) -> Path:
        path = self.root / name
        if not path.exists():
            tmp = self.root / f"building-{os.getpid()}-{name}"
            if tmp.exists():
                shutil.rmtree(tmp) if tmp.is_dir() else tmp.unlink()
            build(tmp)
            os.replace(tmp, path)
        return path


_BASELINE: Baseline | None = None


def baseline() -> Baseline:
    """The baseline of this process: under $VEHID_FUZZ_BASELINE, else a folder in the system's temp dir."""
    global _BASELINE
    if _BASELINE is None:
        import tempfile

        root = os.environ.get("VEHID_FUZZ_BASELINE") or Path(tempfile.gettempdir()) / f"vehid-fuzz-{os.getuid()}"
        _BASELINE = Baseline(Path(root))
    return _BASELINE


# ------------------------------------------------------------------------------------------ running


def files_in(folder: Path) -> set[str]:
    """Every path below `folder` (relative), symlinks not followed."""
    out = set()
    for dirpath, dirnames, filenames in os.walk(folder, followlinks=False):
        for n in dirnames + filenames:
            out.add(str(Path(dirpath, n).relative_to(folder)))
    return out


def leftovers(before: set[str], after: set[str], code: int | None) -> tuple[str, ...]:
    """New paths a command must not leave: any after a failure (exit 2), a temporary, lock or checkpoint after
    a success."""
    new = sorted(after - before)
    if code == 0:
        new = [p for p in new if any(part in Path(p).name for part in LEFTOVER)]
    return tuple(new)


class _Hang(Exception):
    pass


def _alarm(signum, frame):
    raise _Hang


def run_in_process(case: Case, folder: Path, timeout: float = 60.0) -> Outcome:
    """Run the case through typer's CliRunner in this process (fast; a hang is cut by SIGALRM, a crash takes the
    process down, which a test run shows too)."""
    from typer.testing import CliRunner

    from vehid_cli.cli.app import app

    before = files_in(folder)
    old = signal.signal(signal.SIGALRM, _alarm)
    signal.setitimer(signal.ITIMER_REAL, timeout)
    t0 = time.perf_counter()
    env = dict(case.env)
    cwd = os.getcwd()
    try:
        os.chdir(folder)
        result = CliRunner().invoke(app, list(case.args), env=env or None, catch_exceptions=True)
        hung = isinstance(result.exception, _Hang)
        code = None if hung else result.exit_code
        text = (result.stdout or "") + (result.stderr or "")
        if result.exception is not None and not hung and not isinstance(result.exception, SystemExit):
            text += f"\nTraceback (in process): {result.exception!r}"
    except _Hang:
        code, text = None, ""
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)
        os.chdir(cwd)
    seconds = time.perf_counter() - t0
    return Outcome(case, code, None, text, leftovers(before, files_in(folder), code), seconds)


def run_in_subprocess(case: Case, folder: Path, timeout: float = 60.0) -> Outcome:
    """Run the case as a user does (`python -m vehid_cli`), in its own process group: a crash is its signal, a
    hang is killed after `timeout` s."""
    before = files_in(folder)
    env = {**os.environ, **dict(case.env)}
    env.pop("VEHID_DEBUG", None)
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        [sys.executable, "-m", "vehid_cli", *case.args], cwd=folder, env=env, stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True, errors="replace", start_new_session=True,
    )  # fmt: skip
    try:
        text, _ = proc.communicate(timeout=timeout)
        code, sig = proc.returncode, None
        if code < 0:
            code, sig = None, -code
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        text, _ = proc.communicate()
        code, sig = None, None
    seconds = time.perf_counter() - t0
    return Outcome(case, code, sig, text, leftovers(before, files_in(folder), code), seconds)


def make_case(name: str, seed: int, index: int, folder: Path) -> Case:
    """Case `index` of family `name` in a campaign of `seed`: its own stream, its files written in `folder`."""
    stream = np.random.SeedSequence(seed, spawn_key=(sum(map(ord, name)), index))
    folder.mkdir(parents=True, exist_ok=True)
    return FAMILIES[name](np.random.default_rng(stream), folder)


def plan(seed: int, cases: int, names: Sequence[str] | None = None) -> list[tuple[str, int]]:
    """`cases` (family, index) pairs, the families taken in turn."""
    names = sorted(names or FAMILIES)
    return [(names[i % len(names)], i // len(names)) for i in range(cases)]
