"""The rigs' figures (issue 24): `vehid simulate --plot` draws the inputs and every channel over the configured
rig's clean response; `vehid report --plots` draws, per campaign and measured run, every channel against the rig at
the estimate. The difference drawn is measured minus the model at the estimate: on data of the independent
simulator (tests/test_quarter_car.py) with white noise, its power per sample over sigma² is near 1."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import ROOT, cli, read_png, sets
from tests.test_quarter_car import CONFIG, NAMES, SIGMA, independent, write_yaml
from vehid_cli.config import load_config
from vehid_cli.systems import build_system
from vehid_cli.systems.lumped_plots import trace

HALF = ROOT / "configs" / "half_car" / "pitch_plane.yaml"


@pytest.mark.parametrize("config", [ROOT / "configs" / "quarter_car" / "lab_rig.yaml", HALF])
def test_simulate_plot_draws_a_rig(tmp_path, config):
    res = cli("simulate", config, "-o", tmp_path / "s.csv", "--plot", tmp_path / "s.png",
              *sets(["simulation.duration=3"]))  # fmt: skip
    assert res.exit_code == 0, res.output
    read_png(tmp_path / "s.png")


def test_report_plots_draw_measured_against_fitted(tmp_path):
    system = build_system(load_config(write_yaml(tmp_path, CONFIG)))
    t, u = system.rigs[0].t, system.rigs[0].u
    clean = independent(np.array([CONFIG["quarter_car"][n] for n in NAMES]) * 1.05, t, u[:, 0], u[:, 1])
    rng = np.random.default_rng(8)
    cols = ["t", "body", "wheel", "defl", "bacc", "road1", "force"]
    table = np.column_stack([t, *(clean[k] + SIGMA[k] * rng.standard_normal(t.size) for k in cols[1:5]), u])
    data = tmp_path / "run.csv"
    np.savetxt(data, table, delimiter=",", header=",".join(cols), comments="")
    measured = dict(CONFIG, road={"input": "measured", "actuator_force": "measured"},
                    identify=dict(CONFIG["identify"], start="config", algorithm={"name": "lsq"}))  # fmt: skip
    config = write_yaml(tmp_path, measured, "measured.yaml")
    res = cli("identify", config, "--data", data, "--jobs", 1, "-o", tmp_path / "fit.h5")
    assert res.exit_code == 0, res.output
    res = cli("report", tmp_path / "fit.h5", "--plots", tmp_path / "figs")
    assert res.exit_code == 0, res.output
    read_png(tmp_path / "figs" / "fitted_fit.png")
    from vehid_cli.campaign.results import read_campaign_h5

    campaign = read_campaign_h5(tmp_path / "fit.h5")
    fitted = build_system(campaign.config, str(data))
    model = {f: v[0] for f, v in fitted.outputs(campaign.records[0].estimate[None, :], 0).items()}
    drawn = trace(fitted, 0, fitted.reference(0)[0], model)
    for name, _, y, m, _ in drawn.channels:  # the difference drawn is the noise the simulator added
        assert np.mean(((y - m) / SIGMA[name]) ** 2) == pytest.approx(1.0, abs=0.1), name
