"""Load and fault injection (issue 7), through the scripts in benchmarks/: a sweep of many small campaigns over 2
workers keeps every result with bounded memory; random interruptions and damage lose nothing, hide nothing."""

from __future__ import annotations

import importlib.util
import json
import subprocess
import sys

import pytest

from tests.conftest import ROOT


def bench_module(name: str):
    spec = importlib.util.spec_from_file_location(name, ROOT / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_a_small_load_keeps_every_result(tmp_path):
    result = bench_module("bench_load").run_load(6, tmp_path / "sweep")
    assert result["files_verified"] == 6 and result["report_rows"] == 30


@pytest.mark.slow
@pytest.mark.parametrize("executor", ["local", "dask"])
def test_200_campaigns_over_2_workers(tmp_path, executor):
    if executor == "dask":
        pytest.importorskip("distributed")
    result = bench_module("bench_load").run_load(200, tmp_path / "sweep", executor=executor)
    assert result["files_verified"] == 200 and result["report_rows"] == 1000
    assert result["memory_bounded"], result
    assert result["peak_tree_rss_mib"] < 1024, result


@pytest.mark.slow
def test_fault_injection(tmp_path):
    """Random SIGKILL/SIGTERM/SIGINT at random moments of campaigns and sweeps, random damage to files."""
    res = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "fault_injection.py"), "--identify", "6", "--sweep", "3",
         "--damage", "60", "--seed", "7", "--json", str(tmp_path / "trials.json")],
        capture_output=True, text=True, cwd=ROOT, timeout=1800,
    )  # fmt: skip
    assert res.returncode == 0, res.stdout + res.stderr
    trials = json.loads((tmp_path / "trials.json").read_text())
    assert len(trials) == 69 and all(t["ok"] for t in trials)
