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


# ------------------------------------------------------------------------------------------ hostile YAML (issue 22)


def load_text(tmp_path, text: str | bytes, overrides=()):
    path = tmp_path / "c.yaml"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(InputError) as info:
        load_config(path, overrides)
    return str(info.value)


def billion_laughs(levels: int = 10, width: int = 10) -> str:
    lines = [f"a0: &a0 [{', '.join(['lol'] * width)}]"]
    lines += [f"a{i}: &a{i} [{', '.join([f'*a{i - 1}'] * width)}]" for i in range(1, levels)]
    return "\n".join(lines) + "\n"


def test_an_alias_bomb_is_refused_at_once_naming_the_file_and_the_limit(tmp_path):
    import time

    text = billion_laughs()
    assert len(text) < 1300  # the 1.2 kB bomb: 10**10 values
    t0 = time.perf_counter()
    msg = load_text(tmp_path, text)
    assert time.perf_counter() - t0 < 1.0
    assert msg.startswith(f"{tmp_path / 'c.yaml'}: refused at line ") and "more than 20000 values" in msg


@pytest.mark.parametrize(
    "text, expected",
    [
        ("a: &a [*a]\n", "circular reference"),
        ("a: &a\n  b: *a\n", "circular reference"),
        ("vehicle: " + "[" * 5000 + "]" * 5000 + "\n", "nested more than 64 levels deep"),
        ("road: " + "{a: " * 100 + "1" + "}" * 100 + "\n", "nested more than 64 levels deep"),
        ("vehicle:\n  m: " + "9" * 5000 + "\n", "an integer of 5000 characters (at most 400)"),
        ("x: [" + ",".join(["1"] * 30000) + "]\n", "more than 20000 values"),
        ("a: 1\nb: 2\na: 3\n", "key 'a' is given twice"),
        ("x: !!python/object/apply:os.system ['true']\n", "could not determine a constructor"),
        ("a: 1\nb: \x00\n", "line 2, column 4: character #x0000 is not allowed in YAML"),
    ],
)
def test_hostile_yaml_is_refused_with_the_line_and_the_limit(tmp_path, text, expected):
    msg = load_text(tmp_path, text)
    assert msg.startswith(str(tmp_path / "c.yaml")) and expected in msg, msg
    assert "\n" not in msg


def test_a_config_file_over_the_size_limit_is_refused_before_parsing(tmp_path):
    msg = load_text(tmp_path, BASE_CONFIG.read_text() + "#" + "x" * 300_000 + "\n")
    assert "config file larger than 262144 bytes" in msg


def test_invalid_utf8_names_the_byte(tmp_path):
    msg = load_text(tmp_path, BASE_CONFIG.read_bytes()[:100] + b"\xff\xfe" + BASE_CONFIG.read_bytes()[100:])
    assert "not utf-8 text (byte 100" in msg


def test_anchors_and_merges_within_the_limits_still_work(tmp_path):
    text = BASE_CONFIG.read_text().replace("  kf: 45000", "  kf: &k 45000").replace("  kr: 80000", "  kr: *k")
    path = tmp_path / "c.yaml"
    path.write_text(text)
    assert load_config(path).vehicle.kr == 45000


def test_set_values_go_through_the_same_limits():
    for value, expected in [("&a [*a]", "circular reference"), ("[" * 100, "nested more than 64")]:
        with pytest.raises(InputError, match=expected):
            load_config(BASE_CONFIG, [f"vehicle.m={value}"])
    with pytest.raises(InputError, match="expects dotted.key=value"):
        load_config(BASE_CONFIG, [".".join(["a"] * 100) + "=1"])


# ------------------------------------------------------------------------------------------ ranges (issue 22)


@pytest.mark.parametrize(
    "override, expected",
    [
        ("vehicle.cr=1e30", "'vehicle.cr': must be in [0, 1e+08], got '1e30'"),
        ("vehicle.m=1e-300", "'vehicle.m': must be in [0.1, 1e+06]"),
        ("vehicle.kf=.inf", "'vehicle.kf': expected a finite number"),
        ("road.bump.heights=[0.05, 2, 0.04, 0.05]", "'road.bump.heights.1': must be in [-1, 1], got 2"),
        ("identify.seed=18446744073709551616", "'identify.seed': must be in [0, 9223372036854775807]"),
        ("identify.runs=9223372036854775808", "'identify.runs': must be in [1, 100000]"),
        ("identify.algorithm.population=1000000", "'identify.algorithm.population': must be in [2, 10000]"),
        ("simulation.duration=2000", "more than 1,000,000"),
        ("identify.limits.m=[1e-300, 1e300]", "leaves its physical range [0.1, 1e+06]"),
        ("identify.bounds=[0.5, 2000]", "'identify.bounds.1': must be in (0, 1000]"),
    ],
)
def test_numbers_out_of_their_range_name_the_range(override, expected):
    msg = error_of(overrides=[override])
    assert expected in msg, msg


def test_damper_numbers_out_of_their_range_name_the_range():
    from tests.conftest import ROOT

    damper = ROOT / "configs" / "dampers" / "synthetic_bingham.yaml"
    with pytest.raises(InputError, match=r"the sawtooth holds 1e\+11 samples of dt = 0.002 s; keep it below 2,000,000"):
        load_config(damper, ["bench.excitation=sawtooth", "bench.velocity=1e-9"])
    for override, expected in [
        ("bench.cycles=1e-293", "fewer than 3 samples"),
        ("damper.parameters.c0=1e30", "'damper.parameters.c0': must be in [-1e+12, 1e+12]"),
        ("damper.parameters.c0=-5", "outside the physical range [0, inf] of c0"),
        ("identify.seed=-1", "'identify.seed': must be in [0, 9223372036854775807]"),
    ]:
        with pytest.raises(InputError) as info:
            load_config(damper, [override])
        assert expected in str(info.value), str(info.value)


def test_a_huge_value_is_quoted_clipped():
    msg = error_of(overrides=["vehicle.m=" + "x" * 100_000])
    assert len(msg) < 600 and "(100002 characters)" in msg  # its repr, quotes included
    msg = error_of(overrides=["identify.algorithm.name=" + "a" * 100_000])
    assert len(msg) < 600 and "(100000 characters)" in msg
