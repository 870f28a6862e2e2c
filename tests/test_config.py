"""Config loading: the shipped config, overrides, and one clear InputError per kind of mistake."""

from __future__ import annotations

import pytest
import yaml

from tests.conftest import BASE_CONFIG, PAPER_CAR
from vehid_cli.config import apply_overrides, config_from_dict, load_config
from vehid_cli.core.errors import InputError


def raw_base():
    return yaml.safe_load(BASE_CONFIG.read_text())


def test_base_config_is_the_paper_setup(base_config):
    cfg = base_config
    assert cfg.vehicle.values() == pytest.approx(PAPER_CAR)
    assert cfg.road.V == pytest.approx(20 / 3.6)
    assert cfg.road.bump.heights == (0.05, 0.04, 0.04, 0.05)
    assert cfg.road.bump.length == 0.1 and cfg.road.bump.start_time == 0.1
    assert (cfg.simulation.duration, cfg.simulation.dt) == (3.0, 0.001)
    assert cfg.identify.unknowns == ("m", "Ix", "Iy", "a1", "b1")
    assert cfg.search_box()["m"] == pytest.approx((910.0, 1690.0))
    assert cfg.noise.level == 0.1


def test_overrides_are_typed_and_nested():
    cfg = load_config(BASE_CONFIG, ["noise.level=0", "road.bump.heights=[0.1, 0.1, 0.1, 0.1]", "vehicle.m=1400"])
    assert cfg.noise.level == 0
    assert cfg.road.bump.heights == (0.1,) * 4
    assert cfg.vehicle.m == 1400.0


def test_override_does_not_touch_the_original():
    raw = raw_base()
    apply_overrides(raw, ["vehicle.m=1"])
    assert raw["vehicle"]["m"] == 1300


def test_digest_ignores_formatting_but_not_values():
    a = load_config(BASE_CONFIG)
    b = config_from_dict(yaml.safe_load(a.to_yaml()))
    assert a.digest() == b.digest()
    assert load_config(BASE_CONFIG, ["vehicle.m=1301"]).digest() != a.digest()


def error_of(raw=None, overrides=()):
    with pytest.raises(InputError) as info:
        config_from_dict(apply_overrides(raw or raw_base(), overrides), source="car.yaml")
    return str(info.value)


def test_unknown_key_suggests_the_right_one():
    msg = error_of(overrides=["vehicle.mass=1300"])
    assert "car.yaml" in msg and "'vehicle.mass'" in msg and "did you mean 'm'" in msg


def test_unknown_section_suggests_the_right_one():
    msg = error_of(overrides=["simulaton.dt=0.001"])
    assert "'simulaton'" in msg and "did you mean 'simulation'" in msg


def test_wrong_type_names_key_and_value():
    msg = error_of(overrides=["vehicle.m=heavy"])
    assert "'vehicle.m'" in msg and "number" in msg and "heavy" in msg


def test_negative_mass():
    msg = error_of(overrides=["vehicle.m=-5"])
    assert "'vehicle.m'" in msg and "must be in [0.1, 1e+06], got -5" in msg


def test_a1_outside_the_wheelbase():
    raw = raw_base()
    del raw["vehicle"]["a2"]
    raw["vehicle"]["wheelbase"] = 2.6
    raw["vehicle"]["a1"] = 3.0
    msg = error_of(raw)
    assert "'vehicle.a1'" in msg and "outside the wheelbase" in msg


def test_missing_key():
    raw = raw_base()
    del raw["vehicle"]["kf"]
    assert "'vehicle.kf': required key is missing" in error_of(raw)


def test_bad_choice_lists_the_choices():
    msg = error_of(overrides=["simulation.integrator=euler"])
    assert "'simulation.integrator'" in msg and "'exact'" in msg and "euler" in msg


def test_identify_unknown_not_a_parameter():
    msg = error_of(overrides=["identify.unknowns=[m, Iz]"])
    assert "'identify.unknowns'" in msg and "'Iz' is not a vehicle parameter" in msg


def test_bounds_that_exclude_the_truth():
    msg = error_of(overrides=["identify.bounds=[1.1, 1.3]"])
    assert "'identify.bounds'" in msg and "excludes" in msg


def test_a1_search_range_leaving_the_wheelbase():
    msg = error_of(overrides=["identify.bounds=[0.5, 2.5]"])
    assert "wheelbase" in msg


def test_population_below_two():
    assert "'identify.algorithm.population'" in error_of(overrides=["identify.algorithm.population=1"])


def test_zero_runs():
    assert "'identify.runs'" in error_of(overrides=["identify.runs=0"])


def test_road_needs_a_speed_and_a_source():
    raw = raw_base()
    del raw["road"]["speed_kmh"]
    assert "speed_kmh" in error_of(raw)
    raw = raw_base()
    del raw["road"]["bump"]
    assert "'bump'" in error_of(raw)


@pytest.mark.parametrize(
    "text, expected",
    [("vehicle: [1, 2\n", "not valid YAML at line"), ("- a\n- b\n", "mapping of sections"), ("", "'vehicle'")],
)
def test_bad_yaml_files(tmp_path, text, expected):
    path = tmp_path / "bad.yaml"
    path.write_text(text)
    with pytest.raises(InputError, match=expected) as info:
        load_config(path)
    assert str(path) in str(info.value)


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="config file not found"):
        load_config(tmp_path / "nope.yaml")


def test_malformed_set(tmp_path):
    with pytest.raises(InputError, match="dotted.key=value"):
        load_config(BASE_CONFIG, ["vehicle.m"])
    with pytest.raises(InputError, match="is a value, not a section"):
        load_config(BASE_CONFIG, ["sensors.kind=acc"])


def test_an_override_that_breaks_a_valid_config_is_named_by_its_option():
    from vehid_cli.config import Override

    with pytest.raises(InputError) as info:
        load_config(BASE_CONFIG, ["noise.level=0.2", Override("identify.runs=0", "--runs")])
    assert str(info.value) == "--runs: 'identify.runs': must be in [1, 100000], got 0"
    with pytest.raises(InputError) as info:
        load_config(BASE_CONFIG, ["noise.levle=0.1", Override("identify.runs=3", "--runs")])
    assert str(info.value).startswith("--set noise.levle=0.1: 'noise.levle': unknown key; did you mean 'level'?")
    # a2=null alone is invalid, wheelbase repairs it, a1 breaks it again: the last one is named
    sets = ["vehicle.a2=null", "vehicle.wheelbase=2.6", "vehicle.a1=2.7"]
    with pytest.raises(InputError, match=r"^--set vehicle.a1=2.7: 'vehicle.a1': .*outside the wheelbase"):
        load_config(BASE_CONFIG, sets)


def test_an_invalid_config_file_is_named_even_with_overrides(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(BASE_CONFIG.read_text().replace("  level: 0.10", "  levle: 0.10"))
    with pytest.raises(InputError, match=rf"^{bad}: 'noise.levle': unknown key"):
        load_config(bad, ["identify.runs=2"])
