"""An effect is one plug-in: the toy effect of `tests/toy_effect.py` (one file, outside the package), once registered,
is a config's `vehicle.effects` entry, simulated by the compiled kernel, and a candidate `vehid diagnose` tries and
names; removed again, the library is as before."""

from __future__ import annotations

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from tests import toy_effect
from tests.conftest import BASE_CONFIG
from vehid_cli.cli.app import app
from vehid_cli.config import load_config
from vehid_cli.identify.experiment import build_experiment
from vehid_cli.models.effects import LIBRARY, effect_rows, register, unregister
from vehid_cli.systems.vehicle.diagnosis import diagnose

NAME = toy_effect.EFFECT.name


@pytest.fixture
def toy():
    before = tuple(LIBRARY)
    register(toy_effect.EFFECT)
    yield toy_effect.EFFECT
    unregister(NAME)
    assert tuple(LIBRARY) == before


def test_the_toy_effect_is_simulated_and_its_force_is_the_law(toy, tmp_path):
    raw = yaml.safe_load(BASE_CONFIG.read_text())
    raw["simulation"].update(integrator="rk4", duration=1.5)
    raw["vehicle"]["effects"] = {NAME: {"cq_f": 0.0, "cq_r": 0.0}}
    path = tmp_path / "zero.yaml"
    path.write_text(yaml.safe_dump(raw))
    plain = build_experiment(load_config(BASE_CONFIG, ["simulation.integrator=rk4", "simulation.duration=1.5"]))
    zero = build_experiment(load_config(path))
    np.testing.assert_array_equal(zero.simulate().q, plain.simulate().q)  # zero strength adds exactly nothing
    strong = zero.simulate({f"{NAME}.cq_f": np.array([4000.0]), f"{NAME}.cq_r": np.array([4000.0])})
    assert np.max(np.abs(strong.q[0, :, 0] - plain.simulate().q[:, 0])) > 1e-4  # and a strength moves the body
    es = effect_rows({NAME: {"cq_f": 1000.0, "cq_r": 2000.0}}, 2800.0, 3500.0, (1,))
    v = np.array([0.3, -0.2, 0.1, -0.4])
    f = np.zeros(4)
    es.law(np.zeros(4), v, np.zeros(0), es.rows[0], f, np.zeros(0))  # the composed law, through the registry
    np.testing.assert_allclose(f, np.array([1000.0, 1000.0, 2000.0, 2000.0]) * v * np.abs(v), rtol=1e-15)


def test_vehid_diagnose_offers_and_names_the_toy_effect(toy, tmp_path):
    raw = yaml.safe_load(BASE_CONFIG.read_text())
    raw["simulation"].update(integrator="rk4", duration=1.5)
    raw["vehicle"]["effects"] = {NAME: {"cq_f": 3000.0, "cq_r": 3000.0}}
    truth, data = tmp_path / "truth.yaml", tmp_path / "run.csv"
    truth.write_text(yaml.safe_dump(raw))
    res = CliRunner().invoke(app, ["simulate", str(truth), "-o", str(data), "--set", "noise.level=0.02"])
    assert res.exit_code == 0, res.output
    cfg = load_config(BASE_CONFIG, [
        "identify.objective=wls", "noise.level=0", "identify.truth=config", "identify.algorithm.name=hybrid",
        "identify.budget=600", "simulation.duration=1.5",
    ])  # fmt: skip
    d = diagnose(cfg, data, candidate_budget=40, refit_budget=200, analyse_residuals=False)
    tried = [r.effect for r in d.rounds[0]]
    assert NAME in tried and {"asymmetric_damping", "coulomb_friction", "parameter:cf"} <= set(tried)
    assert d.selected[0] == NAME, (d.selected, [(r.effect, r.statistic) for r in d.rounds[0]][:4])
