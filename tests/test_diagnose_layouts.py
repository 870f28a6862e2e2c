"""vehid diagnose on any sensor layout, logger files and several runs (issue 13 meets issue 6).

The runs come from `examples/make_rig_runs.py`: the four-post rig config's sixteen sensors (tower, floor, dash and
boot accelerometers, wheel accelerometers, deflection potentiometers at 200 Hz) in g and mm, with gravity, biases
and zero offsets (`data.offsets: identify`). The truths are what the runs were written from: the configured car,
or the car with a progressive spring (configs/effects/progressive_spring.yaml's k3) the diagnosed config does not
declare. Fast checks take the pieces one by one against independent truths (the residual layout against explicit
loops, the linearised car's channels against finite differences of the simulator, the residual at the true car
against the noise); the slow ones run the loop (about a minute per run on two cores).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from examples.make_rig_runs import write_rig_run
from tests.conftest import BASE_CONFIG, ROOT, invoke, sets
from vehid_cli.config import load_config
from vehid_cli.core.errors import InputError
from vehid_cli.diagnose.holdout import holdout_blocks
from vehid_cli.diagnose.linear_response import linear_car as _linear_car
from vehid_cli.diagnose.linear_response import responses as _responses
from vehid_cli.diagnose.residuals import analyse, fingerprint_channels
from vehid_cli.diagnose.result import chi2_limit
from vehid_cli.diagnose.unexplained import estimate_unexplained
from vehid_cli.identify.experiment import build_experiment
from vehid_cli.identify.objectives import Objective
from vehid_cli.identify.task import build_task
from vehid_cli.models.fullcar import assemble
from vehid_cli.models.sensors import Layout, Sensor
from vehid_cli.sim.linear import simulate
from vehid_cli.systems import diagnose_config
from vehid_cli.systems.vehicle.diagnosis import holdout_mask

RIG = ROOT / "configs" / "examples" / "four_post_rig.yaml"
SHORT = ["simulation.duration=4", "simulation.integrator=rk4"]  # 4 s of the rig (4000 samples at 1 kHz)
K3 = {"k3_f": 2e7, "k3_r": 3e7}  # configs/effects/progressive_spring.yaml [N/m³]
SPRING = [f"vehicle.effects.progressive_spring.{k}={v:g}" for k, v in K3.items()]
SLOW_CHANNELS = ("defl_fl", "defl_fr", "defl_rr", "defl_rl")  # the potentiometers, 200 Hz on the 1 kHz grid


@pytest.fixture(scope="module")
def rig(tmp_path_factory) -> dict[str, Path]:
    """Clean rig runs (seeds 11, 12) and runs with the undeclared progressive spring (seeds 21, 22)."""
    out = tmp_path_factory.mktemp("rig")
    return {
        "clean": write_rig_run(RIG, out / "clean.mf4", 11, SHORT),
        "spring": write_rig_run(RIG, out / "spring1.mf4", 21, [*SHORT, *SPRING]),
        "spring2": write_rig_run(RIG, out / "spring2.mat", 22, [*SHORT, *SPRING]),
    }


def rig_task(path: Path, overrides=()):
    return build_task(load_config(RIG, [*SHORT, "identify.truth=config", *overrides]), path)


# ------------------------------------------------------------------------------------ the residual's layout


def test_sample_times_follow_the_residual_entries():
    """Each residual entry's time sample, read back from a reference that encodes it (1000 t + channel)."""
    n = 12
    acc = np.add.outer(1000.0 * np.arange(n), np.arange(3))
    disp = np.add.outer(1000.0 * np.arange(n), 10 + np.arange(2))
    observed = {"acc": np.ones((n, 3), dtype=bool), "disp": np.ones((n, 2), dtype=bool)}
    observed["acc"][1::3, 1] = False  # a slow channel: every third sample only
    observed["disp"][::2, 0] = False
    sigma = {"acc": np.ones(3), "disp": np.ones(2)}
    zero = {"acc": np.zeros((n, 3)), "disp": np.zeros((n, 2))}
    for obs in (None, observed):
        objective = Objective("wls", {"acc": acc, "disp": disp}, sigma, observed=obs)
        r = objective.residuals(zero)
        expected = [
            t for f, ref in (("acc", acc), ("disp", disp)) for t in range(n) for c in range(ref.shape[1])
            if obs is None or obs[f][t, c]
        ]  # fmt: skip
        np.testing.assert_array_equal(objective.sample_times(), expected)
        np.testing.assert_array_equal(r // 1000, expected)
        assert objective.sample_times().size == objective.size


def test_paper_holdout_mask_is_the_corner_layout_of_before():
    """The paper's layout (4 channels per family, no mask): held-out samples repeated per channel, per family."""
    cfg = load_config(BASE_CONFIG, ["identify.objective=wls"])
    task = build_task(cfg)
    held = holdout_blocks(task.experiment.t.size)
    np.testing.assert_array_equal(holdout_mask(task, task.reference(0)), np.tile(np.repeat(held, 4), 2))


# ------------------------------------------------------------------------------------ the linearised car


def test_linear_car_channels_are_the_sensitivity_of_every_sensor_kind():
    """A strut force f = d (the front corners' deflection) is what raising kf by 1 N/m adds: the linear car's
    response at each channel of a layout with every sensor kind equals d(channel)/d(kf) of the simulator's."""
    cfg = load_config(RIG, ["simulation.duration=2"])
    exp = build_experiment(cfg)
    layout = Layout(
        (
            Sensor("a_cg", "body_acc"),
            Sensor("a_off", "body_acc", x=-0.4, y=0.3, origin="corner2"),
            Sensor("a_w3", "wheel_acc", corner=3),
            Sensor("z_off", "body_disp", x=0.7, y=-0.2, origin="rear_axle"),
            Sensor("z_w1", "wheel_disp", corner=1),
            Sensor("d_2", "deflection", corner=2),
            Sensor("d_4", "deflection", corner=4),
        )
    )
    p = exp.parameters()

    def outputs(kf: float) -> dict[str, np.ndarray]:
        q = dict(p, kf=np.asarray(kf))
        resp = simulate(assemble(q), exp.road, exp.dt, "exact", layout.points(q))
        return layout.read(resp), resp

    kf, h = float(p["kf"]), 1.0
    (up, _), (down, _), (_, resp) = outputs(kf + h), outputs(kf - h), outputs(kf)
    mats = assemble(p)
    defl = resp.q[:, :3] @ mats.G.T - resp.q[:, 3:]
    U = np.zeros((exp.t.size, 4, 1))
    U[:, :2, 0] = defl[:, :2]
    car = _linear_car(mats, exp.dt, layout, layout.points(p))
    s = _responses(car, U)
    for family in layout.families:
        linear = (car.out_s[family] @ s + car.out_u[family] @ U)[..., 0]
        fd = (up[family] - down[family]) / (2 * h)
        scale = np.max(np.abs(fd), axis=0)
        assert np.all(scale > 0)
        np.testing.assert_allclose(linear / scale, fd / scale, atol=2e-3, err_msg=family)


# ------------------------------------------------------------------------------------ residual analysis


def test_residual_analysis_of_a_rig_run_at_the_true_car(rig):
    """At the true car the residual of every channel is the noise, the 200 Hz potentiometers at their own
    samples (NaN between them, a spectrum up to 100 Hz); the offsets (gravity, biases, zeros) are profiled out,
    without that the accelerometers' residual would be about 200 sigma."""
    task = rig_task(rig["clean"])
    assert task.offsets and task.observed is not None
    ref = task.reference(0)
    an = analyse(task, ref, task.names, task.truth)
    n = task.experiment.t.size
    own = np.isfinite(an.residual).sum(axis=0)
    for name, count, chi2, white in zip(an.channels, own, an.chi2_channel, an.whiteness, strict=True):
        assert abs(count - n / 5) <= 1 if name in SLOW_CHANNELS else count == n, (name, count)
        assert abs(chi2 - 1.0) < 5 * np.sqrt(2.0 / count), (name, chi2)
        assert white.p_value > 1e-4, (name, white.p_value)
    slow = [an.channels.index(c) for c in SLOW_CHANNELS]
    assert np.all(np.isnan(an.psd[slow][:, an.freq > 100.0 + 1e-9]))
    assert np.all(np.isfinite(an.psd[slow][:, an.freq < 99.0]))
    assert an.chi2_per_sample == pytest.approx(np.sum(np.nan_to_num(an.residual) ** 2) / own.sum())
    p = {k: float(v) for k, v in task.experiment.parameters().items()}
    picks = fingerprint_channels(task.experiment.layout, p, an.channels)
    assert [an.channels[j] for j in picks] == ["acc_tower_fl", "acc_tower_fr", "acc_tower_rr", "acc_tower_rl"]
    json.dumps(an.summary())  # plain numbers
    unprofiled = analyse(task.__class__(**{**task.__dict__, "offsets": False}), ref, task.names, task.truth)
    assert np.min(unprofiled.chi2_channel[:8]) > 1e3  # gravity over a 5 mg noise floor


def test_unexplained_force_on_the_rig_layout(rig):
    """The non-parametric strut force from the rig's channels (masks and offsets honoured): nothing at the true
    car of a clean run; the cubic stiffening of an undeclared progressive spring where there is one."""
    linear = ["simulation.integrator=exact"]  # the declared car is linear
    clean = rig_task(rig["clean"], linear)
    nothing = estimate_unexplained(clean, clean.reference(0), clean.names, clean.truth)
    assert nothing.p_value > 1e-3 and not nothing.significant
    task = rig_task(rig["spring"], linear)
    found = estimate_unexplained(task, task.reference(0), task.names, task.truth)
    assert found.significant and found.p_value < 1e-10
    assert found.acts_on["variable"] == "deflection"
    for axle in (found.front, found.rear):  # kf, kr are fitted: the cubic modulo its line
        assert axle.g.resembles.best == "progressive_spring", axle.g.resembles.r2
        assert axle.g.resembles.r2["progressive_spring"] > 0.95
    assert found.resembles == "progressive_spring"
    assert found.chi2_after < 1.1 < found.chi2_before


# ------------------------------------------------------------------------------------ input


def test_the_config_runs_are_diagnosed_when_no_data_is_given(rig, monkeypatch):
    """data.files names the runs as for identify (--data wins); a run that is not there: exit 2 naming it."""
    code, _, err = invoke("diagnose", RIG, "--data", rig["clean"].with_name("missing.mf4"))
    assert code == 2 and "missing.mf4" in err
    monkeypatch.setattr(
        "vehid_cli.systems.vehicle.diagnosis.diagnose", lambda cfg, data, validate, log=None, progress=None: data
    )
    files = f"data.files=[{rig['clean']},{rig['spring']}]"
    assert diagnose_config(RIG, [files]) == (str(rig["clean"]), str(rig["spring"]))
    assert diagnose_config(RIG, [files], data=rig["spring"]) == str(rig["spring"])  # --data wins, as a path string


def test_a_damper_takes_one_data_run():
    damper = ROOT / "configs" / "dampers" / "brfd_bingham.yaml"
    with pytest.raises(InputError, match="one --data run"):
        diagnose_config(damper, data=["a.csv", "b.csv"])


# ------------------------------------------------------------------------------------ the loop


def k3_estimates(doc: dict) -> dict[str, float]:
    return {k: doc["after"]["estimates"][f"progressive_spring.{k}"] for k in K3}


@pytest.mark.slow
def test_an_undeclared_progressive_spring_is_found_on_the_rig(rig, tmp_path):
    code, out, err = invoke(
        "diagnose", RIG, "--data", rig["spring"], "--json", tmp_path / "d.json", "--plots", tmp_path,
        *sets(["simulation.duration=4", "identify.truth=config"]),
    )  # fmt: skip
    assert code == 0, err
    doc = json.loads((tmp_path / "d.json").read_text())
    assert doc["selected"] == ["progressive_spring"], doc["notes"]
    assert doc["verdict"].startswith("found: progressive_spring")
    for k, v in k3_estimates(doc).items():
        assert v == pytest.approx(K3[k], rel=0.1), k
    assert doc["before"]["chi2_per_sample"] > 1.5 and doc["after"]["chi2_per_sample"] <= doc["chi2_limit"]
    assert set(doc["after"]["residual"]["chi2_per_channel"]) == set(load_config(RIG).sensor_layout().channel_names)
    assert doc["after"]["nre_percent"] < 1.0 < doc["before"]["nre_percent"]
    assert (tmp_path / "spring1-residual.png").exists()


@pytest.mark.slow
def test_a_clean_rig_run_is_adequate(rig):
    d = diagnose_config(RIG, ["simulation.duration=4", "identify.truth=config"], rig["clean"])
    assert d.selected == () and d.verdict.startswith("adequate"), (d.verdict, d.notes)
    assert d.after.chi2_per_sample <= chi2_limit(d.before.analysis.residual.size)


@pytest.mark.slow
def test_two_rig_runs_jointly_find_the_spring(rig, tmp_path):
    """One parameter set over both runs: the same finding, the joint J before and after, each run's residual."""
    code, out, err = invoke(
        "diagnose", RIG, "--data", rig["spring"], "--data", rig["spring2"], "--json", tmp_path / "d.json",
        *sets(["simulation.duration=4", "identify.truth=config"]),
    )  # fmt: skip
    assert code == 0, err
    doc = json.loads((tmp_path / "d.json").read_text())
    assert doc["selected"] == ["progressive_spring"], doc["notes"]
    assert doc["data_files"] == [str(rig["spring"]), str(rig["spring2"])]
    assert " + " in doc["validation"]
    for k, v in k3_estimates(doc).items():
        assert v == pytest.approx(K3[k], rel=0.1), k
    before, after = doc["before"], doc["after"]
    assert before["J"] > 1.5 and after["J"] < 1.05 and doc["steps"][0]["J_before"] == before["J"]
    per_run = after["residual_per_file"]
    assert list(per_run) == doc["data_files"]
    for summary in per_run.values():  # each run is at the noise on its own
        assert summary["chi2_per_sample"] <= doc["chi2_limit"]
    assert f"J {before['J']:.4g} -> {after['J']:.4g}" in out
