"""Shared fixtures: the paper's config, paths to the independent data in ../shared."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from vehid_cli.config import Config, load_config

ROOT = Path(__file__).resolve().parents[1]
BASE_CONFIG = ROOT / "configs" / "gokdag2015" / "base.yaml"
SHARED = ROOT.parent / "shared"
VEHICLE_DATA = SHARED / "data" / "vehicle"

PAPER_CAR = dict(
    m=1300.0, mf=40.0, mr=65.0, Ix=500.0, Iy=2500.0, a1=1.3, a2=1.3, b1=0.75, b2=0.75,
    kf=45000.0, kr=80000.0, ktf=200000.0, ktr=200000.0, kR=50000.0, cf=2800.0, cr=3500.0,
)  # fmt: skip


@pytest.fixture
def base_config() -> Config:
    return load_config(BASE_CONFIG)


def needs_shared(path: Path) -> Path:
    """The path of independent test data in ../shared; skipped on a bare clone, a failure in CI."""
    if not path.exists():
        if os.environ.get("CI"):
            pytest.fail(f"independent data not found at {path} (CI must have ../shared beside the repo)")
        pytest.skip(f"independent data not found at {path}")
    return path


def vehid(*args, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    """Run `python -m vehid_cli ARGS` as a user does: a real process, captured stdout/stderr, exit code."""
    return subprocess.run([sys.executable, "-m", "vehid_cli", *map(str, args)], capture_output=True, text=True, cwd=cwd)


def cli(*args, cwd: Path | None = None):
    """Run the command line in this process (typer's CliRunner: stdout and stderr apart, stderr not a terminal)."""
    from typer.testing import CliRunner

    from vehid_cli.cli import app

    runner = CliRunner()
    if cwd is None:
        return runner.invoke(app, [str(a) for a in args], prog_name="vehid")
    old = Path.cwd()
    os.chdir(cwd)
    try:
        return runner.invoke(app, [str(a) for a in args], prog_name="vehid")
    finally:
        os.chdir(old)
