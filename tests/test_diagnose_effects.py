"""Issue 6, acceptance 2: for every effect of the library, data simulated with it and diagnosed with the plain
linear car gets that effect ranked first, and the NRE falls; data without any effect gets nothing selected,
over several seeds. Through the CLI, as a user runs it (slow: about 20 s per diagnosis)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.conftest import BASE_CONFIG, ROOT

EFFECTS = sorted(p.stem for p in (ROOT / "configs" / "effects").glob("*.yaml"))
VALIDATION_ROAD = ["--set", "road.bump.heights=[0.03,0.06,0.06,0.03]", "--set", "road.speed_kmh=15"]


def vehid(*args):
    res = subprocess.run([sys.executable, "-m", "vehid_cli", *map(str, args)], capture_output=True, text=True, cwd=ROOT)
    assert res.returncode == 0, res.stderr
    return res


def diagnose(truth_config, tmp_path, seed):
    train, valid, out = tmp_path / "train.csv", tmp_path / "valid.csv", tmp_path / "diag.json"
    vehid("simulate", truth_config, "-o", train, "--set", "noise.level=0.05", "--seed", seed)
    vehid("simulate", truth_config, "-o", valid, "--set", "noise.level=0.05", "--seed", seed + 1, *VALIDATION_ROAD)
    vehid("diagnose", BASE_CONFIG, "--data", train, "--validate", valid, "--set", "identify.algorithm.name=hybrid",
          "--set", "identify.truth=config", "--json", out)  # fmt: skip
    return json.loads(out.read_text())


@pytest.mark.slow
@pytest.mark.parametrize("effect", EFFECTS)
def test_the_effect_in_the_data_ranks_first_and_the_nre_falls(tmp_path, effect):
    doc = diagnose(ROOT / "configs" / "effects" / f"{effect}.yaml", tmp_path, seed=1)
    assert doc["candidates"][0]["effect"] == effect
    assert doc["selected"][0] == effect
    assert doc["after"]["nre_percent"] < doc["before"]["nre_percent"] / 5
    assert doc["after"]["chi2_per_sample"] < 1.1


@pytest.mark.slow
@pytest.mark.parametrize("seed", [11, 12, 13])
def test_no_effect_selects_nothing(tmp_path, seed):
    doc = diagnose(BASE_CONFIG, tmp_path, seed=seed)
    assert doc["selected"] == []
