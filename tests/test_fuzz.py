"""Bad input, exhaustively (issues 7, 12): random and mutated configs, road and bench files and sweep
--vary/--shard options thrown at the commands.

Whatever the input, a command exits 0 or 2 (never 1, never a traceback), and when it fails it leaves no
output file, finished or half-written, behind.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, event, given, settings
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


# ------------------------------------------------------------------------------------------ sweeps

SWEEP_KEYS = {  # valid keys: (valid values, each cheap to run; invalid values)
    "noise.level": (["0", "0.05", "0.2"], ["-1", "nan", "1e999", "abc", "[1, 2]", "{a: 1}", "null"]),
    "identify.algorithm.name": (["de", "lsq", "cpso"], ["pso", "DE", "null"]),
    "identify.objective": (["f1", "f2", "wls"], ["f3", "1"]),
    "identify.seed": (["1", "2", "2015"], ["-1", "1.5", "x", "1e30"]),
    "sensors": (["acc", "disp", "both"], ["all", "[acc]"]),
    "identify.algorithm.population": (["4", "5"], ["0", "-2", "x"]),
}
ODD_KEYS = ["nosuch.key", "noise", "identify", "noise..level", " noise.level ", "vehicle.mass", "identify.runs.x"]
SWEEP_SMALL = [
    "simulation.duration=0.5", "identify.runs=1", "identify.algorithm.iterations=1",
    "identify.algorithm.population=4", "identify.algorithm.name=de",
]  # fmt: skip


@st.composite
def vary_items(draw, max_values=3):
    """One --vary string: mostly KEY=V1,V2 of valid values, else odd keys, separators, values or arbitrary text."""
    kind = draw(st.integers(0, 9))
    if kind == 0:
        return draw(st.text(max_size=30))
    if kind == 1:
        key, pool = draw(st.sampled_from(ODD_KEYS)), ["1", "a"]
    else:
        key = draw(st.sampled_from(list(SWEEP_KEYS)))
        valid, invalid = SWEEP_KEYS[key]
        pool = valid if kind >= 5 else valid + invalid + ["", " ", "[1,", "'q'"]
    values = draw(st.lists(st.sampled_from(pool), min_size=1, max_size=max_values, unique=kind >= 5))
    sep = "=" if kind >= 4 else draw(st.sampled_from(["", "==", ":", "="]))
    return f"{key}{sep}" + draw(st.sampled_from([",", ", "])).join(values)


SHARDS = st.one_of(
    st.none(),
    st.sampled_from(["1/1", "1/2", "2/2", "2/3", " 1 / 2 "]),
    st.sampled_from(["3/2", "0/1", "1/0", "a/b", "1-2", "", "-1/2", "２/２", "1/2/3"]),
    st.builds(lambda k, n: f"{k}/{n}", st.integers(-2, 5), st.integers(-2, 5)),
    st.text(max_size=8),
)


def tiny_sweep_config(d: Path) -> Path:
    raw = yaml.safe_load(yaml.safe_dump(BASE))
    raw["simulation"].update(duration=0.5)
    raw["identify"].update(runs=1, algorithm={"name": "de", "population": 4, "iterations": 1})
    path = d / "base.yaml"
    path.write_text(yaml.safe_dump(raw))
    return path


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(items=st.lists(vary_items(), max_size=3), shard=SHARDS)
def test_sweep_planning_accepts_or_names_the_problem(tmp_path_factory, items, shard):
    """parse_vary, parse_shard and plan_sweep on random --vary/--shard input: an InputError naming the option, or a
    plan of exactly the Cartesian product, one distinct file in the output directory each; nothing is written."""
    from vehid_cli.campaign.sweep import parse_shard, parse_vary, plan_sweep
    from vehid_cli.core.errors import InputError

    d = tmp_path_factory.mktemp("plan")
    config = tiny_sweep_config(d)
    out = d / "out"
    try:
        k, n = parse_shard(shard)
    except InputError as exc:
        assert "--shard" in str(exc)
    else:
        assert 1 <= k <= n
    try:
        variations = parse_vary(items)
    except InputError as exc:
        assert "--vary" in str(exc) or "at least one" in str(exc)
        return
    assert variations and len({v.key for v in variations}) == len(variations)
    assert all(v.key and v.values and all(v.values) for v in variations)
    try:
        planned = plan_sweep(config, [], variations, out)
    except InputError as exc:
        assert str(exc)
    else:
        assert len(planned) == math.prod(len(v.values) for v in variations)
        assert [p.index for p in planned] == list(range(len(planned)))
        assert len({p.path for p in planned}) == len(planned)
        assert all(p.path.parent == out and p.path.suffix == ".h5" for p in planned)
    assert sorted(p.name for p in d.iterdir()) == ["base.yaml"]  # planning writes nothing


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    items=st.lists(vary_items(max_values=2), min_size=1, max_size=2),
    shard=SHARDS,
    out_is_a_file=st.sampled_from([False, False, False, True]),
)
def test_sweep_cli_exits_0_or_2_and_leaves_nothing_on_failure(tmp_path_factory, items, shard, out_is_a_file):
    """`vehid sweep` with random --vary/--shard (a tiny campaign each): exit 0 with index.csv listing the whole
    product and one campaign file per campaign of this shard, or exit 2 with no campaign file and no index."""
    d = tmp_path_factory.mktemp("sweep")
    out = d / "out"
    if out_is_a_file:
        out.write_text("not a directory")
    args = ["sweep", BASE_CONFIG, *[a for item in items for a in ("--vary", item)], "-o", out, "--jobs", 1]
    args += [a for s in SWEEP_SMALL for a in ("--set", s)] + (["--shard", shard] if shard is not None else [])
    code, text = run(*args)
    event(f"exit {code}")
    assert code in (0, 2), (code, text)
    assert "Traceback" not in text and "internal error" not in text, text
    if out_is_a_file:
        assert code == 2 and out.read_text() == "not a directory", text
        return
    if code == 2:
        assert not out.exists() or list(out.iterdir()) == [], (text, list(out.iterdir()))
        return
    from vehid_cli.campaign.sweep import parse_shard, parse_vary

    total = math.prod(len(v.values) for v in parse_vary(items))
    k, n = parse_shard(shard)
    index = (out / "index.csv").read_text().splitlines()
    assert len(index) == 1 + total, index
    mine = len(range(k - 1, total, n))
    assert len(list(out.glob("*.h5"))) == mine
    assert f"{mine} campaign(s) run" in text
    assert not [p.name for p in out.iterdir() if p.name.startswith(".") or p.name.endswith(".partial")]
