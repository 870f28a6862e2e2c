"""Shared fixtures and helpers: the paper's config, paths to the independent data in ../shared, running the CLI."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml

from vehid_cli.config import Config, load_config

ROOT = Path(__file__).resolve().parents[1]
BASE_CONFIG = ROOT / "configs" / "gokdag2015" / "base.yaml"
SHARED = ROOT.parent / "shared"
VEHICLE_DATA = SHARED / "data" / "vehicle"
MEASURED = SHARED / "data" / "measured"

PAPER_CAR = dict(
    m=1300.0, mf=40.0, mr=65.0, Ix=500.0, Iy=2500.0, a1=1.3, a2=1.3, b1=0.75, b2=0.75,
    kf=45000.0, kr=80000.0, ktf=200000.0, ktr=200000.0, kR=50000.0, cf=2800.0, cr=3500.0,
)  # fmt: skip

# a small car campaign: 4 DE runs of 40 evaluations on 1.5 s of the bump
SMALL = [
    "simulation.duration=1.5", "simulation.dt=0.002", "identify.runs=4",
    "identify.algorithm.name=de", "identify.algorithm.population=8", "identify.algorithm.iterations=5",
]  # fmt: skip


@pytest.fixture
def base_config() -> Config:
    return load_config(BASE_CONFIG)


def small_config(*extra) -> Config:
    return load_config(BASE_CONFIG, SMALL + list(extra))


def needs_shared(path: Path) -> Path:
    """The path of independent test data in ../shared; skipped on a bare clone, a failure in CI."""
    if not path.exists():
        if os.environ.get("CI"):
            pytest.fail(f"independent data not found at {path} (CI must have ../shared beside the repo)")
        pytest.skip(f"independent data not found at {path}")
    return path


def needs_shared_data_of(config: Path) -> Path:
    """A config that reads measured data (`data.file`, `data.validate`, relative to the config's directory):
    each of those files through needs_shared."""
    data = (yaml.safe_load(config.read_text()) or {}).get("data") or {}
    for name in [data.get("file"), *(data.get("validate") or [])]:
        if name:
            needs_shared((config.parent / name).resolve())
    return config


# ------------------------------------------------------------------------------------------ running the CLI


def vehid(*args, cwd=ROOT, env=None, timeout=None) -> subprocess.CompletedProcess[str]:
    """`vehid ARGS` as a user runs it: a real process (`python -m vehid_cli`), its text output captured."""
    cmd = [sys.executable, "-m", "vehid_cli", *map(str, args)]
    return subprocess.run(cmd, capture_output=True, text=True, cwd=cwd, env=env, timeout=timeout)


def invoke(*args) -> tuple[int, str, str]:
    """`vehid ARGS` in this process (typer's CliRunner): exit code, stdout, stderr."""
    from typer.testing import CliRunner

    from vehid_cli.cli.app import app

    result = CliRunner().invoke(app, [str(a) for a in args])
    return result.exit_code, result.stdout or "", result.stderr or ""


def sets(items) -> list[str]:
    """`--set` options for each `key=value` of items."""
    return [x for s in items for x in ("--set", s)]


# ------------------------------------------------------------------------------------------ output files


def read_png(path) -> np.ndarray:
    """A figure's pixels; fails unless the file is a PNG of at least 200 x 150 pixels with something drawn on it
    (not one flat colour)."""
    from matplotlib.image import imread

    assert Path(path).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", f"{path} is not a PNG"
    pixels = imread(path)
    assert pixels.shape[0] >= 150 and pixels.shape[1] >= 200, (path, pixels.shape)
    assert np.ptp(pixels[..., :3]) > 0.5, f"{path} is blank"
    return pixels


def h5_content(path) -> dict:
    """Every dataset of a campaign file (provenance attributes such as the creation time excluded)."""
    out = {}
    with h5py.File(path) as h5:
        h5.visititems(lambda name, obj: out.__setitem__(name, obj[()]) if isinstance(obj, h5py.Dataset) else None)
        out["config_yaml"] = h5.attrs["config_yaml"]
    return out


def assert_same_content(a, b) -> None:
    """Two campaign files hold the same numbers (the per-run wall times aside)."""
    ca, cb = h5_content(a), h5_content(b)
    assert ca.keys() == cb.keys()
    for key in ca:
        if key == "runs/wall_s":
            continue
        np.testing.assert_array_equal(ca[key], cb[key], err_msg=key)


# ------------------------------------------------------------------------------------------ processes (Linux /proc)


def children(pid: int) -> list[int]:
    out = []
    for task in os.listdir(f"/proc/{pid}/task"):
        with open(f"/proc/{pid}/task/{task}/children") as fh:
            out += [int(c) for c in fh.read().split()]
    return out


def running(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def cli(*args, cwd: Path | None = None):
    """Run the command line in this process (typer's CliRunner: stdout and stderr apart, stderr not a terminal)."""
    from typer.testing import CliRunner

    from vehid_cli.cli.app import app

    runner = CliRunner()
    if cwd is None:
        return runner.invoke(app, [str(a) for a in args], prog_name="vehid")
    old = Path.cwd()
    os.chdir(cwd)
    try:
        return runner.invoke(app, [str(a) for a in args], prog_name="vehid")
    finally:
        os.chdir(old)
