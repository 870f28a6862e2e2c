"""`--save-config` (issue 23, SPEC section 6): the identified car or damper as a config. Round trips: simulate a run,
identify it with --save-config, identify again from the saved config; the second fit starts at the first's estimate
(the search box centred on it) and lands on the same values within a small fraction of the interval. The derived
keys (a2 with the wheelbase kept), an effect section from a diagnosis, files named relative to the config, bad
paths."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
import pytest
import yaml

from tests.conftest import BASE_CONFIG, ROOT, cli, sets
from vehid_cli.config import load_config
from vehid_cli.config.save import Identified, save_config
from vehid_cli.report.saved_config import diagnosis_found

BINGHAM = ROOT / "configs" / "dampers" / "synthetic_bingham.yaml"
CAR = sets(["identify.algorithm.name=hybrid", "identify.objective=wls", "simulation.duration=2.0"])


def identify(tmp_path, config, data, name, extra=()):
    """identify CONFIG --data DATA --save-config NAME.yaml: (JSON, its half-widths of the 95 % interval, the saved
    config's path)."""
    saved, doc, h5 = tmp_path / f"{name}.yaml", tmp_path / f"{name}.json", tmp_path / f"{name}.h5"
    res = cli("identify", config, "--data", data, *extra, "--jobs", 1, "-o", h5, "--json", doc, "--save-config", saved)
    assert res.exit_code == 0, res.output
    assert f"wrote {saved}" in res.stdout
    with h5py.File(h5, "r") as f:  # the interval of one fit: 1.96 x the bound's sd at the estimate (the file's)
        names = [n.decode() if isinstance(n, bytes) else str(n) for n in f["parameters"][()]]
        est = np.asarray(f["runs/estimate"][0])
        half = 1.96 * np.abs(est) * np.asarray(f["crlb/re_sd_percent"][()]) / 100
    return json.loads(doc.read_text()), dict(zip(names, half, strict=True)), saved


@pytest.mark.parametrize("system", ["car", "damper"])
def test_identify_save_config_round_trip(tmp_path, system):
    config, extra = (BASE_CONFIG, CAR) if system == "car" else (BINGHAM, [])
    run = tmp_path / "run.csv"
    assert cli("simulate", config, "-o", run, *extra).exit_code == 0
    first, half, saved = identify(tmp_path, config, run, "first", extra)
    cfg = load_config(saved)
    values = cfg.parameter_values() if system == "car" else cfg.damper.parameters
    box = cfg.search_box()
    for name, estimate in first["mean"].items():
        assert values[name] == estimate  # the value in place, to the last digit
        lo, hi = box[name]  # bounds are factors of the configured value: the box is now centred on the estimate
        assert lo == pytest.approx(cfg.identify.bounds[0] * estimate) and hi == pytest.approx(
            cfg.identify.bounds[1] * estimate
        )
    if system == "car":
        assert cfg.identify.start == "auto"  # measured data: the fit starts at the configured values, the estimate
        assert cfg.vehicle.a1 + cfg.vehicle.a2 == pytest.approx(2.6) and cfg.vehicle.b1 + cfg.vehicle.b2 == 1.5
    text = saved.read_text()
    for name in first["mean"]:
        line = next(x for x in text.splitlines() if x.strip().startswith(f"{name}:"))
        lo, hi = (float(v) for v in line.split("95 % interval [")[1].split("]")[0].split(","))
        mean = first["mean"][name]
        assert lo == pytest.approx(mean - half[name], rel=1e-5) and hi == pytest.approx(mean + half[name], rel=1e-5)
        assert "run.csv" in line and line.split("]")[1].strip().split()[0] == first["units"][name].split()[0]

    assert cli("simulate", saved, "-o", tmp_path / "again.csv").exit_code == 0
    second, _, _ = identify(tmp_path, saved, run, "second")
    for name, estimate in first["mean"].items():
        assert abs(second["mean"][name] - estimate) < 0.05 * half[name], name


def test_the_saved_config_keeps_the_wheelbase_and_takes_a_diagnosed_effect(tmp_path):
    """a1 with the wheelbase given (no a2 in the file): only a1 changes; an effect the config lacks gets its section
    (every parameter, shape included) and the rk4 integrator; a freed parameter its value; a measurement-chain
    correction is not a config value."""
    source = tmp_path / "car.yaml"
    raw = yaml.safe_load(BASE_CONFIG.read_text())
    raw["vehicle"].pop("a2")
    raw["vehicle"]["wheelbase"] = 2.6
    source.write_text("# my car\n" + yaml.safe_dump(raw, sort_keys=False))
    after = SimpleNamespace(
        names=("m", "a1", "kf", "hysteresis.alpha_f", "hysteresis.beta", "sensor:acc1:gain"),
        x=np.array([1310.0, 1.25, 50000.0, 4.0e4, 2.0e5, 1.1]),
        ci=np.array([2.0, 0.01, 100.0, 5e3, np.nan, 0.01]),
    )
    found = diagnosis_found(SimpleNamespace(after=after, selected=("hysteresis", "parameter:kf")), ["run.csv"])
    (tmp_path / "out").mkdir()
    target = save_config(source, ["noise.level=0"], found, tmp_path / "out" / "saved.yaml", command="vehid diagnose")
    cfg = load_config(target)
    v = cfg.vehicle
    assert (v.m, v.a1, v.kf, v.wheelbase, v.a2) == (1310.0, 1.25, 50000.0, 2.6, None)
    assert v.effects == {"hysteresis": {"alpha_f": 4.0e4, "beta": 2.0e5}}
    assert cfg.simulation.integrator == "rk4" and cfg.noise.level == 0
    text = target.read_text()
    assert "# my car" in text and "sensor:" not in text.split("selected")[1].split("\n", 1)[1]
    assert "95 % interval [1308, 1312] kg" in text and "beta: 200000.0  # identified (run.csv" in text
    assert "interval unknown" in text


def test_a_wrong_models_saved_config_marks_each_kind_of_interval(tmp_path):
    """Issue 25: where the final model is wrong, each saved value's comment gives the interval assuming the model,
    the one surviving the misfit and, where library terms imitate a law, the one covering the model uncertainty."""
    after = SimpleNamespace(names=("m", "kf"), x=np.array([1310.0, 50000.0]), ci=np.array([2.0, 100.0]),
                            ci_misfit=np.array([6.0, np.nan]))  # fmt: skip
    mu = SimpleNamespace(imitates=True, names=("m",), low=np.array([1296.0]), high=np.array([1318.0]))
    result = SimpleNamespace(after=after, selected=("parameter:kf",), model_uncertainty=mu)
    found = diagnosis_found(result, ["run.csv"])
    target = save_config(BASE_CONFIG, [], found, tmp_path / "saved.yaml", command="vehid diagnose")
    m_line = next(line for line in target.read_text().splitlines() if line.strip().startswith("m:"))
    assert "95 % interval [1308, 1312] kg; assuming the model right" in m_line
    assert "surviving the misfit [1304, 1316]" in m_line
    assert "covering the model uncertainty (library terms imitate a law) [1296, 1318]" in m_line
    kf_line = next(line for line in target.read_text().splitlines() if line.strip().startswith("kf:"))
    assert "misfit" not in kf_line and "assuming" not in kf_line  # one interval: nothing to tell apart


def test_files_named_relative_to_the_config_stay_found(tmp_path):
    """A measured damper's data.file and data.validate are relative to its config: in the saved config they are
    relative to the saved file, wherever it goes."""
    source = ROOT / "configs" / "dampers" / "mr_bingham.yaml"
    cfg = load_config(source)
    name = cfg.identify.unknowns[0]
    found = Identified({name: 1.5 * cfg.damper.parameters[name]}, {name: None}, "a test", (name,))
    (tmp_path / "deep" / "er").mkdir(parents=True)
    target = save_config(source, [], found, tmp_path / "deep" / "er" / "saved.yaml", command="vehid identify")
    again = load_config(target)

    def real(files):
        return [Path(f).resolve() for f in files]

    assert real([again.data.file]) == real([cfg.data.file]) and Path(cfg.data.file).is_file()
    assert real(again.data.validate_files) == real(cfg.data.validate_files)
    assert again.damper.parameters[name] == 1.5 * cfg.damper.parameters[name]
    assert "AT A BOUND" in target.read_text()


@pytest.mark.parametrize("name", ["nodir/x.yaml", "x.txt"])
def test_a_bad_save_config_path_is_exit_2_before_any_work(tmp_path, name):
    res = cli("identify", BINGHAM, "--runs", "1", "-o", tmp_path / "c.h5", "--save-config", tmp_path / name)
    assert res.exit_code == 2, res.output
    assert name.split("/")[0] in res.stderr and not (tmp_path / "c.h5").exists()


def test_diagnose_save_config_writes_the_found_effect_and_the_result_runs(tmp_path):
    """A Bingham damper's bench run with a Bouc-Wen loop: diagnose finds hysteresis; the saved config declares it
    with the fitted loop, and simulate and identify run on it."""
    truth = load_config(BINGHAM, ["damper.effects={hysteresis: {alpha: 5.0e4, beta: 2.0e5, gamma: 2.0e5}}"])
    from vehid_cli.systems import write_simulation

    run, saved = tmp_path / "hyst.csv", tmp_path / "found.yaml"
    write_simulation(truth, run, truth.identify.seed)
    res = cli("diagnose", BINGHAM, "--data", run, "--save-config", saved)
    assert res.exit_code == 0, res.output
    assert "verdict: found: hysteresis" in res.stdout
    cfg = load_config(saved)
    assert set(cfg.damper.effects) == {"hysteresis"}
    assert cfg.damper.effects["hysteresis"]["alpha"] == pytest.approx(5.0e4, rel=0.2)
    assert "hysteresis" in saved.read_text().splitlines()[1]  # the header names what was selected
    assert cli("simulate", saved, "-o", tmp_path / "again.csv").exit_code == 0
    assert cli("identify", saved, "--data", run, "-o", tmp_path / "again.h5", "--jobs", 1).exit_code == 0
