"""Dampers through the command line: simulate -> identify round trip, a measured-data fit, bad input -> exit 2.

The truth of the round trip is the configured parameter set; J is recomputed here from the stored traces with
numpy (Fleps-Dezasse Eq. 7), independently of vehid's cost function.
"""

from __future__ import annotations

import json

import h5py
import numpy as np
import pytest
import yaml

from tests.conftest import MEASURED, ROOT, needs_shared, needs_shared_data_of, read_png, vehid

MR = MEASURED / "mr_damper_labcontrol" / "data"
TRUTH = {"k1": 2000.0, "x0": -0.05, "c0": 1500.0, "fc": 200.0, "v_eps": 0.02}
LEVEL = 0.02  # force noise, fraction of the clean force's std


def synthetic_config(tmp_path, **identify):
    cfg = {
        "system": "damper",
        "damper": {"model": "bingham", "parameters": TRUTH},
        "bench": {"excitation": "sine", "amplitude": 0.025, "frequency": 0.8, "cycles": 2, "dt": 0.002},
        "noise": {"level": LEVEL},
        "identify": {"unknowns": ["k1", "c0", "fc"], "bounds": [0.5, 2.0], "budget": 300, "runs": 3, **identify},
    }
    path = tmp_path / "damper.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def J(measured, model):
    return float(np.mean((measured - model) ** 2) / np.var(measured))


def test_simulate_identify_round_trip(tmp_path):
    config = synthetic_config(tmp_path)
    bench, fig = tmp_path / "bench.csv", tmp_path / "bench.png"
    res = vehid("simulate", config, "-o", bench, "--plot", fig)
    assert res.returncode == 0, res.stderr
    lines = [line for line in bench.read_text().splitlines() if not line.startswith("#")]
    table = np.genfromtxt(lines, delimiter=",", names=True)
    assert table.dtype.names == ("t", "x", "v", "u", "force")
    np.testing.assert_allclose(table["x"], 0.025 * np.sin(2 * np.pi * 0.8 * table["t"]), atol=1e-9)
    read_png(fig)

    # the campaign: 3 runs, each with its own noise; estimates near the truth, J at the noise floor
    out, js = tmp_path / "campaign.h5", tmp_path / "campaign.json"
    res = vehid("identify", config, "-o", out, "--json", js)
    assert res.returncode == 0, res.stderr
    progress = [line.split(" done")[0] for line in res.stderr.splitlines() if " done (" in line]
    assert [p.split(": ")[-1] for p in progress] == ["run 1/3", "run 2/3", "run 3/3"], res.stderr
    assert all(p.startswith("identify nelder-mead/J: ") for p in progress), res.stderr  # off a terminal: plain lines
    doc = json.loads(js.read_text())
    assert doc["runs"] == 3 and doc["truth"] == {n: TRUTH[n] for n in ("k1", "c0", "fc")}
    for name, value in doc["mean"].items():
        assert value == pytest.approx(TRUTH[name], rel=0.03), name
    assert np.allclose(doc["J"], LEVEL**2, rtol=0.3)  # white noise of sigma = LEVEL std(F): J -> LEVEL^2
    assert len(set(doc["J"])) == 3  # three noise realisations
    with h5py.File(out) as h5:
        assert h5.attrs["kind"] == "vehid.campaign" and h5.attrs["system"] == "damper"
        assert "system: damper" in h5.attrs["config_yaml"]
        tr = h5["damper/traces/00"]
        assert J(tr["measured"][()], tr["model"][()]) == pytest.approx(doc["J"][0], rel=1e-9)
        np.testing.assert_allclose(h5["runs/cost"][()], doc["J"], rtol=1e-12)  # J is the campaign's cost
        assert bool(h5["damper/realtime"].attrs["stable"])

    # identify from the simulated file: one fit from a random start, the truth declared
    out2 = tmp_path / "fromfile.h5"
    sets = ["--set", "identify.truth=config", "--set", "identify.start=random"]
    res = vehid("identify", config, "--data", bench, "-o", out2, *sets)
    assert res.returncode == 0, res.stderr
    with h5py.File(out2) as h5:
        est = dict(zip([n.decode() for n in h5["parameters"][()]], h5["runs/estimate"][0], strict=True))
        assert h5.attrs["data_file"] == str(bench)
        measured = h5["damper/traces/00/measured"][()]
    for name, value in est.items():
        assert value == pytest.approx(TRUTH[name], rel=0.05), name
    np.testing.assert_allclose(measured, table["force"], rtol=1e-9)  # the file's force column, unchanged

    # report: markdown and the figure of the run
    res = vehid("report", out, out2, "--format", "md")  # simulated vs measured data: not comparable
    assert res.returncode == 2 and "not comparable" in res.stderr and "data (simulated vs" in res.stderr
    res = vehid("report", out, out2, "--format", "md", "--plots", tmp_path / "figs", "--allow-mixed")
    assert res.returncode == 0, res.stderr
    assert "#### Cost J (Eq. 7)" in res.stdout and "Real-time check" in res.stdout
    figures = list((tmp_path / "figs").glob("*.png"))
    # per bench run the two campaigns' forces overlaid; per campaign and run, measured against its fitted model
    assert sorted(f.name.split("-")[0] for f in figures) == ["fitted", "fitted", "force", "force"], figures
    assert all(read_png(f) is not None for f in figures)


def test_measured_mr_damper_small_window(tmp_path):
    """A Bingham fit on 6 s of ensaio1.1, validated on the same window of ensaio2.1."""
    config = needs_shared_data_of(ROOT / "configs" / "dampers" / "mr_bingham.yaml")
    data, held_out = needs_shared(MR / "ensaio1.1.csv"), needs_shared(MR / "ensaio2.1.csv")
    out = tmp_path / "mr.h5"
    sets = [
        "data.window=[0, 6]", f"data.validate=[{held_out}]", "identify.budget=400",
        "identify.unknowns=[k1, x0, c0, fc]",
    ]  # fmt: skip
    args = [a for s in sets for a in ("--set", s)]
    res = vehid("identify", config, "-o", out, *args)
    assert res.returncode == 0, res.stderr
    raw = np.genfromtxt(data, delimiter=",", names=True)
    with h5py.File(out) as h5:
        train, held = h5["damper/traces/00"], h5["damper/traces/01"]
        keep = slice(0, train["t"].size)
        assert abs(train["t"].size - 600) <= 1  # 6 s at 10 ms (the edge sample depends on round-off)
        np.testing.assert_allclose(train["measured"][()], raw["force_N"][keep])
        np.testing.assert_allclose(train["x"][()], 1e-3 * raw["pos_mm"][keep])
        J_train = J(train["measured"][()], train["model"][()])
        assert J_train == pytest.approx(float(h5["runs/cost"][0]), rel=1e-9)
        held_J = float(h5["damper/validation/J"][0])
        assert J(held["measured"][()], held["model"][()]) == pytest.approx(held_J, rel=1e-9)
    assert J_train < 0.1  # a viscous + friction + spring model explains over 90 % of the force variance


# ------------------------------------------------------------------------------------------ bad input


def bench_csv(tmp_path, mutate=None):
    t = np.arange(200) * 0.01
    x = 10 * np.sin(2 * np.pi * t)
    force = 50 * np.cos(2 * np.pi * t)
    if mutate:
        t, x, force = mutate(t.copy(), x.copy(), force.copy())
    path = tmp_path / "run.csv"
    rows = "\n".join(f"{a:.6g},{b:.6g},{c:.6g}" for a, b, c in zip(t, x, force, strict=True))
    path.write_text("t_s,pos_mm,force_N\n" + rows + "\n")
    return path


def measured_config(tmp_path, data):
    cfg = {
        "system": "damper",
        "damper": {"model": "viscous", "parameters": {"c0": 1000.0}},
        "data": {"file": str(data), "columns": {"time": "t_s", "displacement": "pos_mm", "force": "force_N"},
                 "units": {"displacement": "mm"}},
        "identify": {"unknowns": ["c0"], "budget": 20},
    }  # fmt: skip
    path = tmp_path / "measured.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def _swap(t, x, f):
    t[5], t[6] = t[6], t[5]
    return t, x, f


def _nan(t, x, f):
    f[17] = np.nan
    return t, x, f


def _in_us(t, x, f):  # a time column in µs read as s: the real-time check stepped 2e4 s at 10 µs (149 GiB)
    return t * 1e6, x, f


@pytest.mark.parametrize(
    "mutate, sets, expected",
    [
        (None, ["data.columns.force=force_kN"], ["force_kN", "not in the file"]),
        (None, ["data.units.force=kipp"], ["data.units.force", "force_N", "kipp"]),
        (_swap, [], ["t_s", "increase"]),
        (_nan, [], ["force_N", "NaN"]),
        (None, ["damper.model=bouc_wn"], ["damper.model", "bouc_wen"]),
        (None, ["damper.parameters.c00=5"], ["c00", "did you mean 'c0'"]),
        (_in_us, [], ["t_s", "'data.units.time'", "lasts 1.99e+06 s", "ms or µs"]),
    ],
    ids=["column", "unit", "time", "nan", "model", "parameter", "time_in_us"],
)
def test_bad_input_exits_2_naming_the_column_or_key(tmp_path, mutate, sets, expected):
    config = measured_config(tmp_path, bench_csv(tmp_path, mutate))
    out = tmp_path / "out.h5"
    res = vehid("identify", config, "-o", out, *[a for s in sets for a in ("--set", s)])
    assert res.returncode == 2, (res.stdout, res.stderr)
    for word in expected:
        assert word in res.stderr, (word, res.stderr)
    assert "Traceback" not in res.stderr and not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["measured.yaml", "run.csv"]


STAGED = ROOT / "configs" / "dampers" / "synthetic_force_map_steps.yaml"


def test_a_stage_may_only_name_unknowns(tmp_path):
    from vehid_cli.config import load_config
    from vehid_cli.core.errors import InputError

    raw = yaml.safe_load(STAGED.read_text())
    raw["identify"]["stages"][0]["unknowns"] = ["k1", "x0", "c0"]
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(raw))
    with pytest.raises(InputError, match="'c0' is not one of identify.unknowns"):
        load_config(path)


def test_every_unknown_needs_a_stage():
    from vehid_cli.config import load_config
    from vehid_cli.core.errors import InputError

    with pytest.raises(InputError, match="no stage identifies"):
        load_config(STAGED, ["identify.unknowns=[k1, x0, F_1_1]", "identify.stages=[{name: g, unknowns: [k1, x0]}]"])


@pytest.mark.slow
def test_step_by_step_from_the_cli(tmp_path):
    """The shipped step-by-step config, one run: gas force and map rows come back to 1 %."""
    import json

    out = tmp_path / "fm.h5"
    res = vehid("identify", STAGED, "--set", "identify.runs=1", "-o", out, "--json", tmp_path / "fm.json")
    assert res.returncode == 0, res.stderr
    doc = json.loads((tmp_path / "fm.json").read_text())
    for name in ("k1", "F_1_1", "F_5_2"):
        assert abs(doc["re_percent"][name]) < 1.0, (name, doc["re_percent"][name])


def test_bench_csv_holds_the_shortest_exact_repr(tmp_path):
    """Was %.10g: lossy for the force and x, and a grid time like 0.006 only by luck of rounding."""
    from vehid_cli.io.measurement import read_table
    from vehid_cli.models.bench import BenchHistory
    from vehid_cli.systems.damper.bench import write_bench_csv

    rng = np.random.default_rng(3)
    t = np.arange(50) * 0.002
    x, v, force = (rng.standard_normal(50) for _ in range(3))
    path = tmp_path / "bench.csv"
    write_bench_csv(path, BenchHistory(t=t, x=x, v=v, u=np.zeros(50), force=force), ["a comment"])
    lines = path.read_text().splitlines()
    assert lines[:2] == ["# a comment", "t,x,v,u,force"]
    assert [line.split(",")[0] for line in lines[2:]] == [repr(float(s)) for s in t]
    assert lines[5].split(",")[0] == "0.006"
    table = read_table(path)
    for name, values in (("t", t), ("x", x), ("v", v), ("force", force)):
        np.testing.assert_array_equal(table.column(name), values)


SHIPPED = sorted((ROOT / "configs" / "dampers").glob("*.yaml"))


@pytest.mark.slow
@pytest.mark.parametrize("config", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_every_shipped_damper_config_goes_through_the_one_pipeline(tmp_path, config):
    """identify (2 workers), a rerun that resumes nothing and refuses nothing, and report: every shipped damper
    config, with a small budget, writes the car's campaign layout with system = damper."""
    needs_shared_data_of(config)
    out = tmp_path / f"{config.stem}.h5"
    args = ["identify", config, "-o", out, "--jobs", "2", "--set", "identify.budget=40", "--runs", "2"]
    res = vehid(*args)
    assert res.returncode == 0, res.stderr
    with h5py.File(out) as h5:
        assert h5.attrs["system"] == "damper" and h5.attrs["objective"] == "J"
        measured = bool(h5.attrs["data_file"])
        assert h5.attrs["runs"] == (1 if measured else 2)  # measured data: one fit
        cost, evals = h5["runs/cost"][()], h5["runs/evaluations"][()]
        stages = len(yaml.safe_load(config.read_text())["identify"].get("stages", [])) or 1
        assert np.all(evals <= 40 * stages) and np.all(np.isfinite(cost))
        traces = [h5[f"damper/traces/{k}"] for k in sorted(h5["damper/traces"])]
        first = traces[0]
        assert J(first["measured"][()], first["model"][()]) == pytest.approx(float(first.attrs["J"]), rel=1e-9)
    report = vehid("report", out, "--format", "json")
    assert report.returncode == 0, report.stderr
    doc = json.loads(report.stdout)[0]
    assert doc["system"] == "damper" and doc["J"] == pytest.approx(list(cost), rel=1e-12)


# ------------------------------------------------------------------------------------------ logger formats

BENCH_RATE = 300.0  # Hz, nominal: the stamps jitter by ±10 % of 1/300 s around it
BENCH_N = 1200  # 4 s
BENCH_START = {"k1": 2400.0, "c0": 1200.0, "fc": 250.0}  # the config's values: the start of the fit


def _jittered_bench_run():
    """A Bingham damper (TRUTH) on a 25 mm, 1.5 Hz sine, sampled at ISO time stamps with ±10 % jitter around
    1/300 s (whole microseconds, as an ISO stamp prints them): (t [s], x [m], v [m/s], F [N])."""
    from vehid_cli.models.bench import BenchHistory
    from vehid_cli.models.damper import default_values
    from vehid_cli.systems.damper.fit import DamperSpec

    rng = np.random.default_rng(13)
    steps = (1 + rng.uniform(-0.1, 0.1, BENCH_N - 1)) / BENCH_RATE
    us = np.round(np.concatenate([[0.0], np.cumsum(steps)]) * 1e6).astype(np.int64)
    t = us / 1e6
    w = 2 * np.pi * 1.5
    x, v = 0.025 * np.sin(w * t), 0.025 * w * np.cos(w * t)
    force = DamperSpec("bingham", {**default_values("bingham"), **TRUTH}).simulate(
        BenchHistory(t, x, v, np.zeros(t.size))
    )
    np.testing.assert_allclose(force, 1500 * v + 200 * np.tanh(v / 0.02) + 2000 * (x + 0.05))  # memoryless
    return us, t, x, v, force


def _bench_config(path, data, columns, units=None, **more):
    cfg = {
        "system": "damper",
        "damper": {"model": "bingham", "parameters": {**TRUTH, **BENCH_START}},
        "data": {"file": str(data), "columns": columns, **({"units": units} if units else {}), **more},
        "identify": {"unknowns": ["k1", "c0", "fc"], "bounds": [0.5, 2.0], "budget": 150},
    }
    path.write_text(yaml.safe_dump(cfg))
    return path


def _identify(config, out):
    res = vehid("identify", config, "-o", out)
    assert res.returncode == 0, res.stderr
    with h5py.File(out) as h5:
        names = [n.decode() if isinstance(n, bytes) else n for n in h5["damper/model_names"][()]]
        values = dict(zip(names, h5["damper/model_values"][()], strict=True))
        trace = {k: h5["damper/traces/00"][k][()] for k in ("t", "x", "v", "measured")}
    return {n: float(values[n]) for n in BENCH_START}, trace


@pytest.fixture(scope="module")
def iso_bench(tmp_path_factory):
    """The jittered run as a CSV with ISO time stamps, x in mm, v in mm/s, F in kN; identified once."""
    import datetime

    tmp = tmp_path_factory.mktemp("iso_bench")
    us, t, x, v, force = _jittered_bench_run()
    start = datetime.datetime(2026, 3, 1, 10, 0, 0)
    rows = [
        f"{(start + datetime.timedelta(microseconds=int(u))).isoformat(timespec='microseconds')},"
        f"{float(1e3 * a)!r},{float(1e3 * b)!r},{float(1e-3 * f)!r}"
        for u, a, b, f in zip(us, x, v, force, strict=True)
    ]
    data = tmp / "bench_iso.csv"
    data.write_text("stamp,stroke_mm,speed_mm_s,load_kN\n" + "\n".join(rows) + "\n")
    columns = {"time": "stamp", "displacement": "stroke_mm", "velocity": "speed_mm_s", "force": "load_kN"}
    units = {"displacement": "mm", "velocity": "mm/s", "force": "kN"}
    config = _bench_config(tmp / "iso.yaml", data, columns, units)
    estimates, trace = _identify(config, tmp / "iso.h5")
    return {"tmp": tmp, "t": t, "x": x, "v": v, "force": force, "estimates": estimates, "trace": trace}


def test_bench_csv_with_jittered_iso_stamps_identifies_the_damper(iso_bench):
    """Acceptance item 6: ISO time stamps at a jittered ~300 Hz, mm and kN; the training trace is in SI on a
    uniform ~300 Hz grid, and the fit finds the Bingham damper it was made from."""
    for name, value in iso_bench["estimates"].items():
        assert value == pytest.approx(TRUTH[name], rel=0.02), (name, value)
    trace = iso_bench["trace"]
    t = trace["t"]
    steps = np.diff(t)
    assert t[0] == 0.0 and np.ptp(steps) < 1e-9 * t[-1]  # uniform
    assert 1 / steps.mean() == pytest.approx(BENCH_RATE, rel=0.02)
    assert t[-1] <= iso_bench["t"][-1] and t.size >= 0.97 * BENCH_N
    # the force in N (not kN) and x in m: the written signals, interpolated onto the grid
    truth = np.interp(t, iso_bench["t"], iso_bench["force"])
    assert np.max(np.abs(trace["measured"] - truth)) < 0.01 * np.ptp(iso_bench["force"])
    assert np.max(np.abs(trace["x"] - np.interp(t, iso_bench["t"], iso_bench["x"]))) < 1e-4
    assert np.max(np.abs(trace["v"] - np.interp(t, iso_bench["t"], iso_bench["v"]))) < 2e-3


def _write_mdf(path, t, x, v, force):
    from asammdf import MDF, Signal

    mdf = MDF(version="4.10")
    mdf.append(
        [
            Signal(1e3 * x, t, name="Kolben.Weg[Ist]", unit="mm"),
            Signal(1e3 * v, t, name="Kolben.Geschw", unit="mm/s"),
            Signal(1e-3 * force, t, name="KMD F_ist (Zyl 1)", unit="kN"),
        ]
    )
    mdf.save(path, overwrite=True)
    mdf.close()
    return path


MDF_COLUMNS = {
    "time": "t",
    "displacement": "Kolben.Weg[Ist]",
    "velocity": "Kolben.Geschw",
    "force": "KMD F_ist (Zyl 1)",
}


@pytest.mark.parametrize("kind", ["mf4", "mat"])
def test_the_same_bench_run_as_mdf4_or_mat_gives_the_same_estimates(iso_bench, kind):
    """The same samples at the same stamps in MDF4 (odd channel names; the units the file declares, none in the
    config) and in a MAT v5 struct (units in the config): the same grid, the same data, the same estimates."""
    import scipy.io

    tmp, t, x, v, force = (iso_bench[k] for k in ("tmp", "t", "x", "v", "force"))
    if kind == "mf4":
        data = _write_mdf(tmp / "bench.mf4", t, x, v, force)
        config = _bench_config(tmp / "mdf.yaml", data, MDF_COLUMNS)
    else:
        data = tmp / "bench.mat"
        run = {"time": t, "pos_mm": 1e3 * x, "vel_mm_s": 1e3 * v, "force_kN": 1e-3 * force}
        scipy.io.savemat(data, {"run": run, "note": np.array([1.0, 2.0])})
        columns = {"time": "time", "displacement": "pos_mm", "velocity": "vel_mm_s", "force": "force_kN"}
        units = {"displacement": "mm", "velocity": "mm/s", "force": "kN"}
        config = _bench_config(tmp / "mat.yaml", data, columns, units, variable="run")
    estimates, trace = _identify(config, tmp / f"{kind}.h5")
    ref = iso_bench["trace"]
    np.testing.assert_allclose(trace["t"], ref["t"], rtol=0, atol=1e-12)
    for key in ("x", "v", "measured"):
        np.testing.assert_allclose(trace[key], ref[key], rtol=1e-12, atol=1e-12 * np.max(np.abs(ref[key])))
    for name, value in estimates.items():
        assert value == pytest.approx(iso_bench["estimates"][name], rel=1e-6), (name, value)


def test_a_bench_channel_missing_from_the_mdf4_file_exits_2_listing_the_channels(iso_bench):
    tmp, t, x, v, force = (iso_bench[k] for k in ("tmp", "t", "x", "v", "force"))
    data = _write_mdf(tmp / "missing.mf4", t, x, v, force)
    config = _bench_config(tmp / "missing.yaml", data, {**MDF_COLUMNS, "force": "KMD F_soll"})
    out = tmp / "missing.h5"
    res = vehid("identify", config, "-o", out)
    assert res.returncode == 2, (res.stdout, res.stderr)
    assert str(data) in res.stderr and "'KMD F_soll'" in res.stderr and "not in the file" in res.stderr
    present = res.stderr.split("present: ")[1].strip()
    assert present == "Kolben.Weg[Ist], Kolben.Geschw, KMD F_ist (Zyl 1)", res.stderr
    assert "Traceback" not in res.stderr and not out.exists()


def test_bench_csv_sample_rate_rebuilds_a_rounded_time_column_and_keeps_the_samples(tmp_path):
    """data.sample_rate through the one reader: a time column in ms printed with 5 digits (up to 1 % round-off of
    the step) is rebuilt as k / rate, the samples kept as printed; a rate the column does not follow is an
    error naming data.sample_rate."""
    from vehid_cli.core.errors import InputError
    from vehid_cli.systems.damper.bench import read_bench

    k = np.arange(300)
    x, force = np.sin(k / 10), np.cos(k / 7)
    path = tmp_path / "rounded.csv"
    rows = "\n".join(
        f"{1e3 * k_ / 1024:.5g},{a!r},{b!r}" for k_, a, b in zip(k, x.tolist(), force.tolist(), strict=True)
    )
    path.write_text("t_ms,pos_mm,force_N\n" + rows + "\n")
    columns = {"time": "t_ms", "displacement": "pos_mm", "force": "force_N"}
    units = {"time": "ms", "displacement": "mm"}
    h = read_bench(path, columns, units, sample_rate=1024.0)
    np.testing.assert_array_equal(h.t, k / 1024)
    np.testing.assert_array_equal(h.x, 1e-3 * x)
    np.testing.assert_array_equal(h.force, force)
    np.testing.assert_array_equal(h.u, np.zeros(k.size))
    np.testing.assert_allclose(h.v, np.gradient(1e-3 * x, k / 1024))
    with pytest.raises(InputError) as err:
        read_bench(path, columns, units, sample_rate=900.0)
    assert err.value.key == "data.sample_rate" and "'t_ms'" in str(err.value) and "900 Hz" in str(err.value)


@pytest.mark.parametrize(
    "sets, key",
    [
        (["bench.dt=10"], "bench.dt"),  # was IndexError (exit 1)
        (["bench.cycles=0.0001"], "bench.cycles"),  # was IndexError
        (["bench.excitation=sawtooth", "bench.cycles=0.0001"], "bench.cycles"),  # was np.gradient's ValueError
        (["bench.excitation=sawtooth", "bench.velocity=1e-9"], "bench.cycles"),  # a 1e8 s grid
    ],
)
def test_a_virtual_bench_whose_time_scale_cannot_be_a_run_is_exit_2_naming_the_key(tmp_path, sets, key):
    from tests.conftest import invoke

    out = tmp_path / "out.h5"
    code, stdout, stderr = invoke("identify", synthetic_config(tmp_path), "-o", out, "--runs", "1",
                                  *[a for s in sets for a in ("--set", s)])  # fmt: skip
    assert code == 2, stdout + stderr
    assert f"'{key}'" in stderr and not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["damper.yaml"]
