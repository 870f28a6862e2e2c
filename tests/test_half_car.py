"""The half car (`system: half_car`) against an independent simulator written here: Newton's equations of the pitch
plane written out force by force (not vehid's energy-derived matrices) as a state space run through
`scipy.signal.lsim` (linear interpolation of the road: the first-order hold). Truth off the config; estimates within
4 sd, the bound within 10 % of a finite-difference Fisher information of this simulator, chi² near 1; road-only data
with every scale unknown stops naming the free scale."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from scipy import signal
from typer.testing import CliRunner

from vehid_cli.campaign.runner import run_campaign
from vehid_cli.cli.app import app
from vehid_cli.config import load_config
from vehid_cli.systems import build_system

ALL = ("m", "Iy", "mf", "mr", "a1", "wheelbase", "kf", "kr", "ktf", "ktr", "cf", "cr")
NAMES = ("m", "Iy", "a1", "kf", "kr", "cf", "cr")
CAR = {"m": 650.0, "Iy": 1250.0, "mf": 40.0, "mr": 65.0, "a1": 1.3, "wheelbase": 2.6, "kf": 45000.0, "kr": 80000.0,
       "ktf": 200000.0, "ktr": 200000.0, "cf": 2800.0, "cr": 3500.0}  # fmt: skip
SIGMA = {"acc_front": 0.05, "acc_rear": 0.05, "defl_front": 2e-4, "defl_rear": 2e-4, "bump": 2e-4}
CONFIG = {
    "system": "half_car",
    "half_car": CAR,
    "road": {"input": "config", "speed_kmh": 20, "bump": {"height": 0.05, "start_time": 0.1},
             "random": {"iso_class": "C"}},
    "simulation": {"duration": 5.0, "dt": 0.002},
    "layout": [{"name": "acc_front", "kind": "body_acc", "origin": "front_axle"},
               {"name": "acc_rear", "kind": "body_acc", "origin": "rear_axle", "x": 0.2},
               {"name": "defl_front", "kind": "deflection", "corner": 1},
               {"name": "defl_rear", "kind": "deflection", "corner": 2},
               {"name": "bump", "kind": "body_disp", "x": 0.3}],
    "noise": {"sigma": {"disp": 2e-4, "acc": 0.05}},
    "identify": {"unknowns": list(NAMES), "bounds": [0.7, 1.4], "runs": 20, "seed": 3,
                 "algorithm": {"name": "hybrid", "population": 20, "iterations": 30}},
}  # fmt: skip


def independent(p, t, y1, y2):
    """Channels of the half car p on roads y1 (front), y2 (rear) that start at 0. State [x, th, x1, x2, velocities];
    nose-down pitch th, so the body above the front axle is x - a1 th, above the rear x + a2 th, at xp: x - xp th."""
    a1 = p["a1"]
    a2 = p["wheelbase"] - a1

    def derivative_rows():
        # forces of the front and rear struts on the body (up +), as rows over [x, th, x1, x2, xd, thd, x1d, x2d]
        Ff = -p["kf"] * np.array([1, -a1, -1, 0, 0, 0, 0, 0.0]) - p["cf"] * np.array([0, 0, 0, 0, 1, -a1, -1, 0.0])
        Fr = -p["kr"] * np.array([1, a2, 0, -1, 0, 0, 0, 0.0]) - p["cr"] * np.array([0, 0, 0, 0, 1, a2, 0, -1.0])
        tyre_f = -p["ktf"] * np.array([0, 0, 1, 0, 0, 0, 0, 0.0])
        tyre_r = -p["ktr"] * np.array([0, 0, 0, 1, 0, 0, 0, 0.0])
        xdd = (Ff + Fr) / p["m"]
        thdd = (-a1 * Ff + a2 * Fr) / p["Iy"]  # a front force up pitches the nose up (th down)
        x1dd = (-Ff + tyre_f) / p["mf"]
        x2dd = (-Fr + tyre_r) / p["mr"]
        return np.array([xdd, thdd, x1dd, x2dd])

    acc = derivative_rows()
    A = np.zeros((8, 8))
    A[:4, 4:] = np.eye(4)
    A[4:] = acc
    B = np.zeros((8, 2))
    B[6, 0], B[7, 1] = p["ktf"] / p["mf"], p["ktr"] / p["mr"]
    body = {"acc_front": a1, "acc_rear": -a2 + 0.2, "bump": 0.3}
    rows, feed = [], []
    for name in ("acc_front", "acc_rear"):
        rows.append(acc[0] - body[name] * acc[1])
        feed.append(np.zeros(2))
    rows += [np.array([1, -a1, -1, 0, 0, 0, 0, 0.0]), np.array([1, a2, 0, -1, 0, 0, 0, 0.0])]
    rows.append(np.array([1, -body["bump"], 0, 0, 0, 0, 0, 0.0]))
    feed += [np.zeros(2)] * 3
    _, Y, _ = signal.lsim((A, B, np.array(rows), np.array(feed)), np.column_stack([y1, y2]), t)
    return dict(zip(SIGMA, Y.T, strict=True))


def write_yaml(tmp_path, cfg, name="hc.yaml"):
    path = tmp_path / name
    path.write_text(yaml.safe_dump(cfg))
    return path


@pytest.fixture(scope="module")
def truth_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("hc")
    system = build_system(load_config(write_yaml(tmp, CONFIG)))
    t, u = system.rigs[0].t, system.rigs[0].u
    factors = dict(zip(NAMES, (1.1, 0.9, 1.05, 0.9, 1.1, 1.12, 0.9), strict=True))
    truth = {n: CAR[n] * factors.get(n, 1.0) for n in ALL}
    clean = independent(truth, t, u[:, 0], u[:, 1])
    rng = np.random.default_rng(99)
    noisy = {k: v + SIGMA[k] * rng.standard_normal(v.size) for k, v in clean.items()}
    data = tmp / "run.csv"
    cols = ["t", *SIGMA, "road1", "road2"]
    np.savetxt(data, np.column_stack([t, *noisy.values(), u]), delimiter=",", header=",".join(cols), comments="")
    measured = dict(
        CONFIG,
        road={"input": "measured"},
        identify=dict(
            CONFIG["identify"], start="config", algorithm={"name": "lsq", "population": 2, "iterations": 200}
        ),
    )
    return tmp, truth, data, write_yaml(tmp, measured, "measured.yaml"), t, u, clean


def test_the_simulation_is_the_independent_simulators(truth_run):
    tmp, truth, _, _, t, u, clean = truth_run
    system = build_system(load_config(write_yaml(tmp, CONFIG)))
    ours = system.outputs(np.array([[truth[n] for n in NAMES]]))
    channels = dict(zip(system.channel_names, np.concatenate([ours["acc"][0], ours["disp"][0]], axis=1).T,
                        strict=True))  # fmt: skip
    for name, ref in clean.items():
        assert np.max(np.abs(channels[name] - ref)) < 1e-6 * np.max(np.abs(ref)), name


def test_measured_run_within_4_sd_and_the_bound_is_the_independent_one(truth_run):
    tmp, truth, data, measured, t, u, _ = truth_run
    cfg = load_config(measured)
    campaign = run_campaign(cfg, str(data), jobs=1)
    at = np.array([truth[n] for n in NAMES])
    est = campaign.records[0].estimate
    assert np.all(np.abs(est - at) < 4 * campaign.bound.sd), (est, at, campaign.bound.sd)
    assert 0.9 < campaign.records[0].chi2 < 1.1
    cols = []
    for n in NAMES:
        h = 1e-5 * truth[n]
        up, down = dict(truth), dict(truth)
        up[n] += h
        down[n] -= h
        a, b = independent(up, t, u[:, 0], u[:, 1]), independent(down, t, u[:, 0], u[:, 1])
        cols.append(np.concatenate([(a[k] - b[k]) / (2 * h) * truth[n] / SIGMA[k] for k in SIGMA]))
    J = np.array(cols).T
    sd_ind = np.sqrt(np.diag(np.linalg.inv(J.T @ J))) * at
    ours = build_system(cfg, str(data)).bound(at).sd
    assert np.allclose(ours, sd_ind, rtol=0.10), (ours, sd_ind)


def test_one_track_delays_the_rear(truth_run):
    """input: track reads road1 and gives the rear wheel the same profile wheelbase/speed later."""
    tmp, _, data, _, t, u, _ = truth_run
    cfg = load_config(write_yaml(tmp, dict(CONFIG, road={"input": "track", "speed_kmh": 20}), "track.yaml"))
    rig = build_system(cfg, str(data)).rigs[0]
    delay = CAR["wheelbase"] / (20 / 3.6)
    assert np.allclose(rig.u[:, 1], np.interp(t - delay, t, u[:, 0], left=u[0, 0]))


def test_every_scale_unknown_names_the_free_scale(tmp_path):
    cfg = dict(CONFIG, identify=dict(CONFIG["identify"], unknowns=[n for n in ALL if n != "wheelbase"], runs=1))
    res = CliRunner().invoke(app, ["identify", str(write_yaml(tmp_path, cfg)), "-o", str(tmp_path / "x.h5")])
    assert res.exit_code == 2, res.output
    text = " ".join(res.output.split())
    assert "m, Iy, mf, mr, kf, kr, ktf, ktr, cf, cr scaled by one factor" in text, text


def test_bad_sensor_placement_names_the_key(tmp_path):
    bad = dict(CONFIG, layout=[{"name": "w", "kind": "wheel_disp", "x": 0.2}])
    res = CliRunner().invoke(app, ["simulate", str(write_yaml(tmp_path, bad)), "-o", str(tmp_path / "x.csv")])
    assert res.exit_code == 2 and "layout.0" in res.output and "corner" in res.output, res.output


def test_diagnose_names_the_rear_damper_off(tmp_path, truth_run):
    """A run of the car with its rear damper nearly off (the independent simulator's cr 50 N s/m, the config's
    3500): diagnose frees the known cr (`parameter:cr`), the residual returns to the noise, and cr's interval holds
    the truth."""
    tmp, _, _, _, t, u, _ = truth_run
    broken = dict(CAR, cr=50.0)
    clean = independent(broken, t, u[:, 0], u[:, 1])
    rng = np.random.default_rng(5)
    noisy = {k: v + SIGMA[k] * rng.standard_normal(v.size) for k, v in clean.items()}
    data = tmp_path / "cr_off.csv"
    cols = ["t", *SIGMA, "road1", "road2"]
    np.savetxt(data, np.column_stack([t, *noisy.values(), u]), delimiter=",", header=",".join(cols), comments="")
    cfg = dict(CONFIG, road={"input": "measured"}, identify=dict(CONFIG["identify"], unknowns=["m", "Iy", "kf", "kr"]))
    out = tmp_path / "d.json"
    res = CliRunner().invoke(app, ["diagnose", str(write_yaml(tmp_path, cfg, "d.yaml")), "--data", str(data),
                                   "--json", str(out)])  # fmt: skip
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    assert doc["selected"] == ["parameter:cr"] and doc["verdict"].startswith("found"), doc["verdict"]
    lo, hi = doc["after"]["ci95"]["cr"]
    sd = (hi - lo) / 2 / 1.959964
    assert abs((lo + hi) / 2 - 50.0) < 4 * sd, (lo, hi)
    assert doc["after"]["chi2_per_sample"] < doc["chi2_limit"]


def test_thirty_runs_reach_the_bound(tmp_path):
    """A 30-run campaign on simulated data (bump and ISO road, the rear wheel wheelbase/speed later): NRE/CRLB <= 1.2
    and the mean within 4 standard errors of the truth."""
    cfg = load_config(write_yaml(tmp_path, dict(CONFIG, identify=dict(CONFIG["identify"], runs=30))))
    doc = run_campaign(cfg, jobs=1).to_json()
    assert doc["nre_over_crlb"] <= 1.2, doc["nre_over_crlb"]
    sd = np.array([doc["crlb"]["re_sd_percent"][n] for n in NAMES])
    re = np.array([doc["re_percent"][n] for n in NAMES])
    assert np.all(np.abs(re) < 4 * sd / np.sqrt(30) + 1e-9), (re, sd)
