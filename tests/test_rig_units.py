"""The rigs (issue 24) under issue 23's units: the quarter car's and half car's parameters declare their SI units
where they are declared, `--save-config` writes a rig's identified values back into its section (and a second fit
from the saved config lands where the first did), and the report's tables of a rig show units and the 95 % interval
of the JSON."""

from __future__ import annotations

import json

import pytest

from tests.conftest import ROOT, cli, sets
from vehid_cli.config import load_config

QUARTER = ROOT / "configs" / "quarter_car" / "lab_rig.yaml"
HALF = ROOT / "configs" / "half_car" / "pitch_plane.yaml"
# SPEC section 1 (SI inside): written here, independent of the Unit markers
QUARTER_UNITS = {"ms": "kg", "mu": "kg", "ks": "N/m", "kt": "N/m", "cs": "N s/m", "ct": "N s/m", "force_gain": "-"}
HALF_UNITS = {
    "m": "kg", "Iy": "kg m²", "mf": "kg", "mr": "kg", "a1": "m", "wheelbase": "m", "kf": "N/m", "kr": "N/m",
    "ktf": "N/m", "ktr": "N/m", "cf": "N s/m", "cr": "N s/m",
}  # fmt: skip
FAST = sets(["simulation.duration=6", "identify.algorithm.name=lsq", "identify.start=config"])


@pytest.mark.parametrize(("config", "units"), [(QUARTER, QUARTER_UNITS), (HALF, HALF_UNITS)])
def test_a_rigs_parameters_have_their_si_units(config, units):
    cfg = load_config(config)
    assert cfg.units(units) == units
    assert set(units) == set(cfg.parameter_values())  # every parameter has one


def identify(tmp_path, config, data, name):
    doc, h5, saved = tmp_path / f"{name}.json", tmp_path / f"{name}.h5", tmp_path / f"{name}.yaml"
    res = cli("identify", config, "--data", data, *FAST, "--jobs", 1, "-o", h5, "--json", doc, "--save-config", saved)
    assert res.exit_code == 0, res.output
    return json.loads(doc.read_text()), h5, saved


def test_a_quarter_car_saves_its_identified_values_and_refits_to_them(tmp_path):
    run = tmp_path / "run.csv"
    assert cli("simulate", QUARTER, "-o", run, *FAST, "--set", "quarter_car.ks=950").exit_code == 0
    first, _, saved = identify(tmp_path, QUARTER, run, "first")
    cfg = load_config(saved)
    for name, estimate in first["mean"].items():
        assert getattr(cfg.quarter_car, name) == estimate  # in place, to the last digit
    assert abs(first["mean"]["ks"] - 950) < 4 * first["crlb"]["sd"]["ks"]  # off the config: the data's, not ours
    text = saved.read_text()
    low, high = first["ci95"]["ks"]
    assert f"[{low:.6g}, {high:.6g}] N/m" in text  # the interval in the parameter's unit
    second, _, _ = identify(tmp_path, saved, run, "second")
    for name, estimate in first["mean"].items():
        lo, hi = first["ci95"][name]
        assert abs(second["mean"][name] - estimate) < 0.05 * (hi - lo)


def test_a_rig_report_table_shows_units_and_the_interval(tmp_path):
    run = tmp_path / "run.csv"
    assert cli("simulate", QUARTER, "-o", run, *FAST).exit_code == 0
    doc, h5, _ = identify(tmp_path, QUARTER, run, "fit")
    assert doc["units"] == {n: QUARTER_UNITS[n] for n in doc["parameters"]}
    res = cli("report", h5, "--format", "md")
    assert res.exit_code == 0, res.output
    rows = {c[0]: c for c in ([x.strip() for x in line.strip("|").split("|")] for line in res.stdout.splitlines()
                              if line.startswith("| "))}  # fmt: skip
    assert rows["parameter"][1] == "unit"
    for name in doc["parameters"]:
        assert rows[name][1] == QUARTER_UNITS[name]
        low, high = doc["ci95"][name]
        shown = [float(x) for x in rows[name][4].strip("[]").split(",")]
        assert shown == pytest.approx([low, high], rel=1e-2)


def test_a_half_car_cannot_save_a_diagnosed_effect(tmp_path):
    cfg = load_config(HALF)
    edits = cfg.edits_for({"a1": 1.2, "cf": 1500.0})
    assert [(e.key, e.value) for e in edits] == [("half_car.a1", 1.2), ("half_car.cf", 1500.0)]
    from vehid_cli.core.errors import InputError

    with pytest.raises(InputError, match="coulomb.F"):
        cfg.edits_for({"coulomb.F": 10.0})


def test_the_rigs_diagnose_hears_progress():
    import inspect

    from vehid_cli.systems.half_car.system import HalfCarSystem
    from vehid_cli.systems.quarter_car.system import QuarterCarSystem

    for cls in (QuarterCarSystem, HalfCarSystem):
        assert "progress" in inspect.signature(cls.diagnose).parameters
