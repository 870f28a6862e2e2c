"""Vehicle runs as a data logger records them (issue 13): sensors anywhere, logger files, several runs at once.

The runs come from `examples/make_rig_runs.py` (the README's generator): the four-post rig config's sixteen
sensors written through asammdf (MDF4) and scipy.io.savemat (MAT v5) under odd names, in g and mm, at 1 kHz and
200 Hz, with gravity, biases and zero offsets. The truth is the configured car; the yardstick the Cramér–Rao bound.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from examples.make_rig_runs import write_rig_run
from tests.conftest import ROOT, invoke
from vehid_cli.config import load_config
from vehid_cli.identify.task import JointTask, build_task, build_tasks
from vehid_cli.io.read import read_record
from vehid_cli.systems import build_system

RIG = ROOT / "configs" / "examples" / "four_post_rig.yaml"
SHORT = ["simulation.duration=4"]  # the tests' runs: 4 s of the rig (4000 samples at 1 kHz)


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("rig")
    return {fmt: write_rig_run(RIG, out / f"run_{fmt}.{fmt}", seed, SHORT) for fmt, seed in (("mf4", 11), ("mat", 12))}


def _z_scores(system, estimate: np.ndarray) -> np.ndarray:
    bound = system.bound()
    return (estimate - system.box.truth) / bound.sd


def test_the_generated_files_are_what_a_logger_writes(runs):
    """Odd names, g and mm, two rates, offsets: read back raw, the channels are not in SI and not centred."""
    cfg = load_config(RIG)
    raw = read_record(runs["mf4"], {"a": "ACC_DASH_Z", "p": "POT_FL"}, {"a": "1", "p": "1"})
    assert raw.rates == {"a": 1000.0, "p": 200.0}
    assert 0.9 < np.mean(raw.channel("a")) < 1.1  # gravity, in g
    assert cfg.data.units["defl_fl"] == "mm" and np.ptp(raw.channel("p")) > 5  # millimetres


@pytest.mark.parametrize("fmt", ["mf4", "mat"])
def test_identify_reads_a_logger_file_and_lands_within_the_bound(runs, fmt, tmp_path):
    code, out, err = invoke(
        "identify", RIG, "--data", runs[fmt], "-o", tmp_path / "fit.h5", "--json", tmp_path / "fit.json",
        *sum((["--set", s] for s in [*SHORT, "identify.truth=config"]), []),
    )  # fmt: skip
    assert code == 0, err
    system = build_system(load_config(RIG, [*SHORT, "identify.truth=config"]), runs[fmt])
    doc = json.loads((tmp_path / "fit.json").read_text())
    estimate = np.array([doc["mean"][n] for n in doc["parameters"]])
    z = _z_scores(system, estimate)
    assert np.all(np.abs(z) < 4.5), dict(zip(doc["parameters"], z.round(2), strict=True))
    assert "χ²/sample 1.0" in out or "χ²/sample 0.9" in out


def test_the_bound_matches_the_information_of_the_residuals_by_finite_differences(runs):
    """The CRLB's Fisher information (central differences of the channels, offsets removed by the Schur
    complement, slow channels at their own samples) against J'J of the fit's own weighted residual vector (forward
    differences through the objective: offsets profiled, masks applied): within 5 % for every parameter."""
    task = build_task(load_config(RIG, [*SHORT, "identify.truth=config"]), runs["mat"])
    bound = task.bound()
    problem = task.problem(task.reference(0))
    x0 = task.truth
    h = 1e-6 * np.abs(x0)
    X = np.vstack([x0, x0 + np.diag(h)])
    _, r = problem.residuals(X)
    J = (r[1:] - r[0]) / h[:, None] * np.abs(x0)[:, None]  # d residual / d relative parameter (signs irrelevant)
    sd_fd = 100 * np.sqrt(np.diag(np.linalg.inv(J @ J.T)))
    np.testing.assert_allclose(bound.re_sd_percent, sd_fd, rtol=0.05)
    assert task.observed is not None and task.offsets  # the slow potentiometers and the offsets were in play


def test_two_runs_together_bound_tighter_than_either_alone(runs):
    cfg = load_config(RIG, [*SHORT, "identify.truth=config"])
    joint = build_tasks(cfg, (runs["mf4"], runs["mat"]))
    assert isinstance(joint, JointTask)
    alone = [build_task(cfg, f).bound() for f in runs.values()]
    together = joint.bound()
    for one in alone:
        assert np.all(together.re_sd_percent < one.re_sd_percent)
    # independent runs: the information adds, so the variances combine as 1/v = 1/v1 + 1/v2 for a single unknown
    np.testing.assert_allclose(together.fisher, alone[0].fisher + alone[1].fisher, rtol=1e-12)


def test_joint_identification_on_the_cli(runs, tmp_path):
    code, out, err = invoke(
        "identify", RIG, "--data", runs["mf4"], "--data", runs["mat"], "-o", tmp_path / "joint.h5",
        *sum((["--set", s] for s in SHORT), []),
    )  # fmt: skip
    assert code == 0, err
    assert f"{runs['mf4']} + {runs['mat']}" in out.replace("\n", "")


BAD = {  # --set -> what the message must name (besides the file)
    "data.channels.acc_dash=ACC_DAHS_Z": ["'acc_dash'", "ACC_DAHS_Z", "did you mean 'ACC_DASH_Z'", "present:"],
    "data.units.acc_dash=gee": ["data.units.acc_dash", "unknown unit 'gee'", "did you mean 'g'"],
    "data.window=[10,20]": ["window [10, 20)", "the record spans [0, 3.995] s"],
    "data.resample=false": ["rates differ", "'defl_fl' ('POT_FL') 200 Hz", "'acc_dash' ('ACC_DASH_Z') 1000 Hz"],
    "data.variable=run7": ["variable 'run7' is not in the file", "present:"],
}


@pytest.mark.parametrize("setting", list(BAD))
def test_bad_logger_settings_are_exit_2_naming_file_and_channel(runs, setting, tmp_path):
    code, _, err = invoke(
        "identify", RIG, "--data", runs["mat"], "-o", tmp_path / "x.h5", "--set", setting,
        *sum((["--set", s] for s in SHORT), []),
    )  # fmt: skip
    assert code == 2, err
    assert "Traceback" not in err
    where = "--set" if "units" in setting else str(runs["mat"])
    for part in [where, *BAD[setting]]:
        assert part in err, (part, err)
    assert not (tmp_path / "x.h5").exists()


def test_unknown_unit_in_the_config_file_names_the_config_and_key(tmp_path):
    text = RIG.read_text().replace("acc_dash: g", "acc_dash: gees")
    (tmp_path / "rig.yaml").write_text(text)
    code, _, err = invoke("identify", tmp_path / "rig.yaml", "-o", tmp_path / "x.h5")
    assert code == 2 and str(tmp_path / "rig.yaml") in err and "data.units.acc_dash" in err, err


@pytest.mark.parametrize("suffix", [".csv", ".h5", ".mf4"])
def test_simulate_writes_the_configured_layout(suffix, tmp_path):
    """Every sensor of the layout and the road, under their names, in SI units: the three formats hold the same
    numbers (the same noise stream), and the CSV reads back through the logger reader with the layout's names."""
    out = tmp_path / f"rig{suffix}"
    code, msg, err = invoke("simulate", RIG, "-o", out, *sum((["--set", s] for s in SHORT), []))
    assert code == 0, err
    assert "16 channels" in msg
    cfg = load_config(RIG, SHORT)
    names = cfg.sensor_layout().channel_names
    if suffix == ".h5":
        import h5py

        with h5py.File(out) as h5:
            got = {n.decode() if isinstance(n, bytes) else n: h5["noisy/acc"][:, j]
                   for j, n in enumerate(h5["noisy/acc"].attrs["columns"])}  # fmt: skip
            got.update({n.decode() if isinstance(n, bytes) else n: h5["noisy/disp"][:, j]
                        for j, n in enumerate(h5["noisy/disp"].attrs["columns"])})  # fmt: skip
    else:
        rec = read_record(out, {n: n for n in names})
        got = rec.channels
    assert set(got) == set(names)
    system_run = build_system(cfg)  # the same draw as run 0 of the campaign: identify's data
    ref = system_run.task.reference(0)
    layout = cfg.sensor_layout()
    for family in ("acc", "disp"):
        for j, name in enumerate(layout.names(family)):
            np.testing.assert_allclose(got[name], ref[family][:, j], rtol=0, atol=1e-12 * np.max(np.abs(ref[family])))


@pytest.mark.slow
def test_logger_runs_reach_the_bound_over_30_noise_seeds_alone_and_jointly(tmp_path):
    """Acceptance 1 and 2 of issue 13: an MDF4 run (road A) and a MAT run (road B), 30 noise seeds each (noise and
    offsets redrawn, roads kept): lsq on each file reaches NRE/CRLB <= 1.2, and the two runs identified jointly
    have a smaller bound than either alone and reach it too."""
    cfg = load_config(RIG, [*SHORT, "identify.truth=config"])
    nre = {"mf4": [], "mat": [], "joint": []}
    bounds = {}
    for k in range(30):
        files = {
            fmt: write_rig_run(RIG, tmp_path / f"s{k}.{fmt}", road, SHORT, noise_seed=1000 + 2 * k + i)
            for i, (fmt, road) in enumerate((("mf4", 21), ("mat", 22)))
        }  # fmt: skip
        for key, data in (("mf4", files["mf4"]), ("mat", files["mat"]), ("joint", tuple(files.values()))):
            system = build_system(cfg, data)
            record = system.identify_run(0)
            truth = system.box.truth
            nre[key].append(np.linalg.norm(100 * (record.estimate - truth) / truth))
            if k == 0:
                bounds[key] = system.bound().nre_rms_percent
    ratios = {key: float(np.sqrt(np.mean(np.square(v)))) / bounds[key] for key, v in nre.items()}
    assert bounds["joint"] < min(bounds["mf4"], bounds["mat"])
    print("NRE/CRLB over 30 noise seeds:", {k: round(r, 3) for k, r in ratios.items()}, "bounds:", bounds)
    assert all(0.8 <= ratio <= 1.2 for ratio in ratios.values()), ratios


def test_data_files_in_the_config_are_relative_to_it_and_identified_jointly(runs, tmp_path):
    (tmp_path / "runs").mkdir()
    for f in runs.values():
        (tmp_path / "runs" / f.name).symlink_to(f)
    text = RIG.read_text().replace(
        "  offsets: identify", "  offsets: identify\n  files: [runs/run_mf4.mf4, runs/run_mat.mat]"
    )
    (tmp_path / "rig.yaml").write_text(text)
    cfg = load_config(tmp_path / "rig.yaml", SHORT)
    assert cfg.data.files == tuple(str(tmp_path / "runs" / f.name) for f in runs.values())
    system = build_system(cfg)
    assert system.data_files() == cfg.data.files and system.runs == 1


def test_road_from_two_measured_tracks_delays_the_rear_by_wheelbase_over_speed(tmp_path):
    """track1 under corners 1 and 4, track2 under 2 and 3; the rear meets each track L / V later."""
    from vehid_cli.identify.measured import read_run
    from vehid_cli.io.write import write_record

    t = np.arange(4000) * 1e-3
    tracks = {"track1": 0.01 * np.sin(2 * np.pi * 1.5 * t) * (t > 0.1), "track2": 0.02 * (t > 0.5)}
    channels = {k: (t, v) for k, v in tracks.items()}
    channels["acc1"] = (t, np.zeros_like(t))
    write_record(tmp_path / "tracks.mf4", channels)
    sets = ["road.input=tracks", "road.speed_kmh=null", "road.speed=13", "layout=[{name: acc1, kind: body_acc}]"]
    sets += ["data.channels={}", "data.units={}", "sensors=acc", "identify.objective=wls"]
    cfg = load_config(RIG, sets)
    run = read_run(cfg, tmp_path / "tracks.mf4", ("acc",))
    delay = 2.6 / 13
    np.testing.assert_allclose(run.road[:, 0], tracks["track1"], atol=1e-12)
    np.testing.assert_allclose(run.road[:, 1], tracks["track2"], atol=1e-12)
    later = t - delay
    np.testing.assert_allclose(run.road[:, 3], np.interp(later, t, tracks["track1"], left=0.0), atol=1e-12)
    k = int(np.searchsorted(t, 0.5 + delay + 0.01))
    assert run.road[k, 2] == pytest.approx(0.02) and run.road[int(np.searchsorted(t, 0.5 + delay - 0.01)), 2] == 0.0


def test_a_logger_run_from_the_independent_simulator_identifies_its_own_car(tmp_path):
    """Truth from outside: tests/independent_sim.py (Newton per body through scipy's LSODA, no vehid code) drives a
    car that is not the config's (m, Ix, Iy, a1, b1 off by 4-12 %) over unequal bumps; its channels for a layout of
    non-corner body accelerometers, wheel accelerometers and 200 Hz deflection potentiometers are computed here
    from its coordinates, written as MDF4 in g and mm under odd names with offsets, and `vehid identify` must land
    on the independent car within the bound."""
    from tests import independent_sim as ind
    from vehid_cli.io.write import write_record

    truth = {"m": 1400.0, "Ix": 540.0, "Iy": 2300.0, "a1": 1.35, "b1": 0.72}
    p = {**ind.PAPER_CAR, **truth, "a2": 2.6 - truth["a1"], "b2": 1.5 - truth["b1"]}
    heights, speed, start, length = (0.05, 0.03, 0.03, 0.05), 20 / 3.6, 0.1, ind.BUMP_LENGTH
    car = ind.FullCar(p, None, lambda t: ind.bump_road(t, heights, speed, 2.6, start, length))
    ramp = length / speed
    sim = ind.run(car, ind.time_grid(3.0, 1e-3), [start, start + ramp, start + 2.6 / speed, start + 2.6 / speed + ramp])
    q, qdd = sim["q"], car.evaluate(sim["t"], sim["state"].T)["rate"][7:14].T
    t = sim["t"]
    rng = np.random.default_rng(77)
    G = 9.80665

    def body(qq, x, y):  # vertical motion of the body point (x forward, y toward side 1) from the CG
        return qq[:, 0] + y * qq[:, 1] - x * qq[:, 2]

    # body accelerometers 15 cm inboard of corners 1 and 3 and 0.3 m behind the front axle centre (from the CG)
    points = {"ACC_A": (p["a1"] - 0.15, p["b1"] - 0.10), "ACC_B": (-p["a2"] + 0.15, -p["b2"] + 0.10),
              "ACC_C": (p["a1"] - 0.3, (p["b1"] - p["b2"]) / 2)}  # fmt: skip
    channels, sigma = {}, {"acc": 0.05, "disp": 1e-4}
    for name, (x, y) in points.items():
        channels[name] = (t, (body(qdd, x, y) + sigma["acc"] * rng.standard_normal(t.size)) / G + 1.0)
    for c in (1, 3):
        channels[f"HUB{c}"] = (t, (qdd[:, 2 + c] + sigma["acc"] * rng.standard_normal(t.size)) / G + 0.01)
        cx, cy = {1: (p["a1"], p["b1"]), 3: (-p["a2"], -p["b2"])}[c]
        defl = body(q, cx, cy) - q[:, 2 + c] + sigma["disp"] * rng.standard_normal(t.size)
        channels[f"POT{c}"] = (t[::5], 1e3 * defl[::5] + 3.0)  # 200 Hz, mm, a zero offset of 3 mm
    for i in range(4):
        channels[f"ACT{i + 1}"] = (t, 1e3 * sim["road"][:, i])
    write_record(tmp_path / "independent.mf4", channels)
    layout = (
        "[{name: a, kind: body_acc, origin: corner1, x: -0.15, y: -0.10},"
        " {name: b, kind: body_acc, origin: corner3, x: 0.15, y: 0.10},"
        " {name: c, kind: body_acc, origin: front_axle, x: -0.3, y: 0},"
        " {name: h1, kind: wheel_acc, corner: 1}, {name: h3, kind: wheel_acc, corner: 3},"
        " {name: d1, kind: deflection, corner: 1}, {name: d3, kind: deflection, corner: 3}]"
    )
    names = {"a": "ACC_A", "b": "ACC_B", "c": "ACC_C", "h1": "HUB1", "h3": "HUB3", "d1": "POT1", "d3": "POT3"}
    names.update({f"road{i}": f"ACT{i}" for i in range(1, 5)})
    units = {k: ("g" if k[0] in "abch" else "mm") for k in names}
    sets = [
        f"layout={layout}", "data.channels=" + json.dumps(names), "data.units=" + json.dumps(units),
        "noise.sigma.acc=0.05", "noise.sigma.disp=0.0001", "simulation.duration=3", "identify.unknowns=[m,Ix,Iy,a1,b1]",
        "identify.start=config",
    ]  # fmt: skip
    cfg = load_config(RIG, sets)
    system = build_system(cfg, tmp_path / "independent.mf4")
    estimate = system.identify_run(0).estimate
    bound = system.bound(estimate)
    z = (estimate - np.array([truth[n] for n in system.names])) / bound.sd
    assert np.all(np.abs(z) < 4.5), dict(zip(system.names, z.round(2), strict=True))
    assert system.task.observed is not None and system.task.offsets


def test_a_run_where_the_channels_overlap_by_a_few_samples_names_the_channel_and_the_count(runs, tmp_path):
    """One clock in another time unit (issue 22): the channels overlap for 5 ms; no noise is estimated from 5
    samples (numpy printed 'Mean of empty slice'): exit 2 naming the channel and how many samples it has."""
    from vehid_cli.io.formats import FORMATS

    cfg = load_config(RIG, SHORT)
    names = {ours: cfg.data.channels.get(ours, ours) for ours in cfg.data.channels}
    rec = read_record(runs["mat"], names, {n: "1" for n in names})
    channels = {ours: (rec.t, rec.channel(ours)) for ours in names}
    channels["road1"] = (rec.t[:6], rec.channel("road1")[:6])  # 5 ms of the road, then nothing
    path = tmp_path / "few.mat"
    FORMATS[".mat"].write(path, channels, names, dict.fromkeys(names, ""), start=None, comment="")
    code, out, err = invoke("check", RIG, "--data", path, *sum((["--set", s] for s in SHORT), []))
    assert code == 2, out + err
    assert str(path) in err and "samples of its own" in err and "at least 8" in err and "Warning" not in out + err
