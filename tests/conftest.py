"""Shared fixtures: the paper's config, paths to the independent data in ../shared."""

from __future__ import annotations

import os
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
