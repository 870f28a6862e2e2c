"""Bad input, exhaustively (issue 7): random and mutated configs and road files thrown at the commands.

Whatever the input, a command exits 0 or 2 (never 1, never a traceback), and when it fails it leaves no
output file, finished or half-written, behind.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.conftest import BASE_CONFIG, invoke

BASE = yaml.safe_load(BASE_CONFIG.read_text())
FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])

NASTY_VALUES = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(10**12), max_value=10**12),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(["", "abc", "1e999", "nan", "-inf", "0x10", "[1,2]", "{a: 1}", "🚗"]),
    st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=6),
    st.dictionaries(st.text(max_size=6), st.integers(), max_size=3),
)


def key_paths(node, prefix=()):
    """Every dotted path into a nested mapping (lists count as leaves)."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield prefix + (k,)
            yield from key_paths(v, prefix + (k,))


PATHS = list(key_paths(BASE))


def mutate(raw, path, action, value):
    out = yaml.safe_load(yaml.safe_dump(raw))
    node = out
    for k in path[:-1]:
        node = node[k]
    if action == "delete":
        node.pop(path[-1], None)
    elif action == "set":
        node[path[-1]] = value
    else:  # an unknown key beside it
        node[f"{path[-1]}_typo"] = value
    return out


def quick(raw):
    """Cap a valid simulation duration at 1 s so accepted cases stay fast (invalid ones are left as they are)."""
    sim = raw.get("simulation")
    if isinstance(sim, dict):
        duration = sim.get("duration")
        if isinstance(duration, (int, float)) and not isinstance(duration, bool) and math.isfinite(duration):
            sim["duration"] = min(duration, 1.0)
    return raw


def run(*args):
    """`vehid ARGS` in this process: exit code and all its text."""
    code, out, err = invoke(*args)
    return code, out + err


def assert_clean_failure(code, text, out_dir: Path, produced: list[Path]):
    assert code in (0, 2), (code, text)
    assert "Traceback" not in text and "internal error" not in text, text
    leftovers = [p.name for p in out_dir.iterdir() if p.name.endswith(".tmp") or p.name.startswith(".")]
    assert not leftovers, leftovers
    if code == 2:
        assert not any(p.exists() for p in produced), text


@FUZZ
@given(path=st.sampled_from(PATHS), action=st.sampled_from(["delete", "set", "typo"]), value=NASTY_VALUES)
def test_mutated_configs_exit_0_or_2(tmp_path_factory, path, action, value):
    d = tmp_path_factory.mktemp("cfg")
    raw = quick(mutate(BASE, path, action, value))
    cfg = d / "c.yaml"
    cfg.write_text(yaml.safe_dump(raw, allow_unicode=True))
    out = d / "out.csv"
    code, text = run("simulate", cfg, "-o", out)
    assert_clean_failure(code, text, d, [out])


@FUZZ
@given(text=st.text(max_size=400))
def test_arbitrary_text_as_config(tmp_path_factory, text):
    d = tmp_path_factory.mktemp("txt")
    cfg = d / "c.yaml"
    cfg.write_text(text)
    out = d / "out.csv"
    code, output = run("simulate", cfg, "-o", out)
    assert code == 2 or (code == 0 and out.exists())
    assert_clean_failure(code, output, d, [out])


ROAD_HEADERS = [
    "t,road1,road2,road3,road4",
    "t,road1,road2,road4",
    "road1,road2,road3,road4",
    "t;road1;road2;road3;road4",
]


@FUZZ
@given(
    header=st.sampled_from(ROAD_HEADERS),
    n=st.integers(min_value=0, max_value=60),
    dt=st.sampled_from([1e-3, 2e-3, 0.05, -1e-3, 0.0]),
    jitter=st.sampled_from([0.0, 1e-9, 3e-4]),
    poison=st.sampled_from(["", "nan", "inf", "-inf", "x", "1e400"]),
    poison_at=st.integers(min_value=0, max_value=59),
    scale=st.sampled_from([0.01, 1e6]),
)
def test_mutated_road_files_exit_0_or_2(tmp_path_factory, header, n, dt, jitter, poison, poison_at, scale):
    d = tmp_path_factory.mktemp("road")
    rng = np.random.default_rng(n)
    lines = [header]
    for k in range(n):
        t = k * dt + (jitter * rng.standard_normal() if k else 0.0)
        cells = [repr(float(t))] + [repr(float(scale * v)) for v in rng.random(header.count(",") or 4)]
        if poison and k == poison_at:
            cells[min(1, len(cells) - 1)] = poison
        lines.append(",".join(cells))
    road = d / "road.csv"
    road.write_text("\n".join(lines) + "\n")
    out = d / "out.csv"
    code, text = run("simulate", BASE_CONFIG, "--road", road, "-o", out)
    assert_clean_failure(code, text, d, [out])


@pytest.mark.parametrize("content", [b"", b"\x00\x01\x02", b"\xff\xfe garbage", b"t\n", b"t,road1,road2,road3,road4\n"])
def test_degenerate_road_files(tmp_path, content):
    road = tmp_path / "road.csv"
    road.write_bytes(content)
    out = tmp_path / "out.csv"
    code, text = run("simulate", BASE_CONFIG, "--road", road, "-o", out)
    assert code == 2
    assert_clean_failure(code, text, tmp_path, [out])


IDENTIFY_PATHS = [p for p in PATHS if p[0] in ("identify", "sensors", "noise")]
SMALL_CAMPAIGN = {"runs": 1, "algorithm": {"name": "lsq", "population": 4, "iterations": 3}}


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(path=st.sampled_from(IDENTIFY_PATHS), action=st.sampled_from(["delete", "set", "typo"]), value=NASTY_VALUES)
def test_mutated_identify_sections_exit_0_or_2(tmp_path_factory, path, action, value):
    d = tmp_path_factory.mktemp("ident")
    raw = yaml.safe_load(yaml.safe_dump(BASE))
    raw["identify"].update(SMALL_CAMPAIGN)
    raw["simulation"].update(duration=1.0, dt=0.002)
    raw = mutate(raw, path, action, value)
    cfg = d / "c.yaml"
    cfg.write_text(yaml.safe_dump(raw, allow_unicode=True))
    out, js = d / "c.h5", d / "c.json"
    code, text = run("identify", cfg, "-o", out, "--json", js, "--jobs", 1)
    assert_clean_failure(code, text, d, [out, js])
    assert not (d / "c.h5.partial").exists()


# ------------------------------------------------------------------------------------------ damper bench files

DAMPER_CONFIG = {
    "system": "damper",
    "damper": {"model": "viscous", "parameters": {"k1": 1000.0, "x0": -0.15, "c0": 2000.0}},
    "data": {"columns": {"time": "t_s", "displacement": "pos_mm", "force": "force_N"}, "units": {"displacement": "mm"}},
    "identify": {"unknowns": ["c0"], "bounds": [0.1, 10.0], "budget": 6, "seed": 1},
}
BENCH_HEADERS = [
    "t_s,pos_mm,force_N",
    "t_s,pos_mm,force_N,vel",
    "t_s,pos,force_N",
    "pos_mm,force_N",
    "t_s;pos_mm;force_N",
]


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    header=st.sampled_from(BENCH_HEADERS),
    n=st.integers(min_value=0, max_value=120),
    dt=st.sampled_from([1e-2, 1e-2, 2e-3, 0.0, -1e-2]),
    jitter=st.sampled_from([0.0, 0.0, 1e-9, 4e-3]),
    poison=st.sampled_from(["", "", "", "nan", "inf", "x", "1e400"]),
    poison_at=st.integers(min_value=0, max_value=119),
    force_scale=st.sampled_from([0.0, 1.0, 1e12]),
    data=st.fixed_dictionaries(
        {},
        optional={
            "sample_rate": st.sampled_from([100.0, 1000.0, -5.0, 0.0]),
            "window": st.sampled_from([[0.0, 0.5], [0.2, 0.1], [5.0, 6.0]]),
            "decimate": st.sampled_from([1, 3, 0, 1000]),
            "units": st.sampled_from([{"displacement": "mm"}, {"displacement": "furlong"}, {"force": "kN"}]),
        },
    ),
)
def test_mutated_bench_files_exit_0_or_2(tmp_path_factory, header, n, dt, jitter, poison, poison_at, force_scale, data):
    """Damper bench CSVs (the measured-data path of `vehid identify` for a damper): short, non-uniform, unsorted,
    poisoned, constant or huge files with odd rates, windows and units exit 0 or 2, never a traceback."""
    d = tmp_path_factory.mktemp("bench")
    rng = np.random.default_rng(n)
    lines = [header]
    for k in range(n):
        t = k * dt + (jitter * rng.standard_normal() if k else 0.0)
        x = 10.0 * np.sin(2 * np.pi * t)
        force = force_scale * (500.0 * np.cos(2 * np.pi * t) + rng.standard_normal())
        cells = [repr(float(t)), repr(float(x)), repr(float(force))]  # plain numbers (NumPy 2's repr is np.float64(..))
        cells += [repr(float(x))] * (header.count(",") + 1 - 3)
        if poison and k == poison_at:
            cells[1] = poison
        lines.append((";" if ";" in header else ",").join(cells[: header.count(",") + header.count(";") + 1]))
    bench = d / "bench.csv"
    bench.write_text("\n".join(lines) + "\n")
    raw = yaml.safe_load(yaml.safe_dump(DAMPER_CONFIG))
    raw["data"].update(data)
    cfg = d / "damper.yaml"
    cfg.write_text(yaml.safe_dump(raw))
    out, js = d / "fit.h5", d / "fit.json"
    code, text = run("identify", cfg, "--data", bench, "-o", out, "--json", js)
    assert_clean_failure(code, text, d, [out, js])
