"""`vehid check` on a rig (issue 24): the measurement chain's generic checks beside the configured quarter car's
prediction. A run of the independent simulator of tests/test_quarter_car.py passes every check; the same run with
the body accelerometer's sign flipped fails the sign check on that channel alone (and identify stops, exit 2,
naming data.invert); with the body and wheel columns swapped, the swap check fails on both."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.conftest import cli
from tests.test_quarter_car import CONFIG, NAMES, SIGMA, independent, write_yaml
from vehid_cli.config import load_config
from vehid_cli.systems import build_system

COLUMNS = ["t", "body", "wheel", "defl", "bacc", "road1", "force"]


@pytest.fixture(scope="module")
def rig(tmp_path_factory):
    """The config's car by the independent simulator on the config's inputs, with white noise: the measured config
    and the run's table."""
    tmp = tmp_path_factory.mktemp("rigchecks")
    system = build_system(load_config(write_yaml(tmp, CONFIG)))
    t, u = system.rigs[0].t, system.rigs[0].u
    clean = independent(np.array([CONFIG["quarter_car"][n] for n in NAMES]), t, u[:, 0], u[:, 1])
    rng = np.random.default_rng(24)
    table = np.column_stack([t, *(clean[k] + SIGMA[k] * rng.standard_normal(t.size) for k in COLUMNS[1:5]), u])
    measured = dict(CONFIG, road={"input": "measured", "actuator_force": "measured"})
    return tmp, write_yaml(tmp, measured, "measured.yaml"), table


def check(tmp, config, table, name):
    """vehid check CONFIG --data <table as CSV> --json: {(channel, check): status} of the findings not ok."""
    data, doc = tmp / f"{name}.csv", tmp / f"{name}.json"
    np.savetxt(data, table, delimiter=",", header=",".join(COLUMNS), comments="")
    res = cli("check", config, "--data", data, "--json", doc)
    assert res.exit_code == 0, res.output
    return {(f["channel"], f["check"]): f["status"] for f in json.loads(doc.read_text())["checks"]
            if f["status"] != "ok"}  # fmt: skip


def test_a_clean_rig_run_passes_every_check(rig):
    tmp, config, table = rig
    assert check(tmp, config, table, "clean") == {}


def test_a_flipped_body_accelerometer_fails_its_sign_check_and_identify_stops(rig):
    tmp, config, table = rig
    flipped = table.copy()
    flipped[:, COLUMNS.index("bacc")] *= -1
    found = check(tmp, config, flipped, "flipped")
    assert [k for k, s in found.items() if s == "fail"] == [("bacc", "sign")]
    res = cli("identify", config, "--data", tmp / "flipped.csv", "--jobs", 1, "-o", tmp / "flipped.h5")
    assert res.exit_code == 2 and "data.invert" in res.output and "bacc" in res.output, res.output


def test_swapped_body_and_wheel_columns_fail_the_swap_check(rig):
    tmp, config, table = rig
    swapped = table.copy()
    b, w = COLUMNS.index("body"), COLUMNS.index("wheel")
    swapped[:, [b, w]] = swapped[:, [w, b]]
    found = check(tmp, config, swapped, "swapped")
    assert found[("body", "swap")] == "fail" and found[("wheel", "swap")] == "fail"
    assert not any(s == "fail" for (ch, _), s in found.items() if ch not in ("body", "wheel", "defl"))
