"""Measured against fitted: the channels of a fit on measured data against the model at the estimate (not the
configured car), the residual and its spectrum against the noise floor, worst channel first."""

from __future__ import annotations

import numpy as np
import pytest

from tests.conftest import BASE_CONFIG, read_png
from vehid_cli.campaign.results import read_campaign_h5, write_campaign_h5
from vehid_cli.campaign.runner import run_campaign
from vehid_cli.config import load_config
from vehid_cli.diagnose.residuals import residual_spectrum
from vehid_cli.identify.records import worst_first
from vehid_cli.report.figures import write_plots
from vehid_cli.systems import VehicleSystem
from vehid_cli.systems.vehicle.fitted import campaign_fits, fitted_channels
from vehid_cli.systems.vehicle.plots import first_task

SHORT = ["simulation.duration=1.5", "simulation.dt=0.002"]
FIT = SHORT + [
    "identify.algorithm.name=lsq", "identify.objective=wls", "noise.level=0", "identify.start=config",
    "identify.unknowns=[m, Iy]",
]  # fmt: skip
TRUE_M = 1500.0  # the car that made the data; the config says 1300


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    """A campaign on a simulated measurement of a heavier car than configured, written and read back."""
    d = tmp_path_factory.mktemp("fitted")
    truth = load_config(BASE_CONFIG, SHORT + [f"vehicle.m={TRUE_M}", "noise.level=0.01"])
    data = d / "run.csv"
    VehicleSystem.write_simulation(truth, data, seed=3)
    cfg = load_config(BASE_CONFIG, FIT)
    write_campaign_h5(d / "fit.h5", run_campaign(cfg, data, jobs=1))
    return read_campaign_h5(d / "fit.h5"), d


def test_worst_first_orders_by_chi2_descending_with_unknowns_last():
    chi2 = {"a": 1.0, "b": float("nan"), "c": 7.5, "d": float("inf"), "e": 0.9, "f": 1.0}
    assert worst_first(chi2) == ["d", "c", "a", "f", "e", "b"]
    assert worst_first({}) == []


def test_the_fitted_curve_is_the_model_at_the_estimate(measured):
    campaign, _ = measured
    estimate = campaign.records[0].estimate
    assert estimate[0] == pytest.approx(TRUE_M, rel=0.02)  # the fit found the heavier car
    task = first_task(campaign)
    exp = task.experiment
    # independently: the experiment's own simulation at the estimate, read through the sensors
    model = exp.read(exp.simulate({n: [v] for n, v in zip(campaign.names, estimate, strict=True)}))
    configured = exp.read(exp.simulate())
    fits = {f.name: f for f in fitted_channels(task, estimate)}
    for family in task.families:
        for k, name in enumerate(exp.layout.names(family)):
            f = fits[name]
            data = task.measured[family][:, k]
            np.testing.assert_allclose(f.measured, data)
            np.testing.assert_allclose(f.residual, data - model[family][0, :, k], rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(f.fitted, model[family][0, :, k], rtol=1e-9, atol=1e-12)
            # against the configured car the residual is far bigger: the figure does not show that car
            assert np.mean((data - configured[family][:, k]) ** 2) > 2 * np.mean(f.residual**2)
    # each channel's chi² per sample is what identify recorded for it (through the objective's residuals)
    for name, d in campaign.per_channel.items():
        assert fits[name].chi2_per_sample == pytest.approx(d["chi2_per_sample"], rel=1e-6)


def test_the_residual_spectrum_of_white_noise_sits_on_its_floor():
    rng = np.random.default_rng(0)
    sigma, fs = 0.3, 500.0
    freq, asd = residual_spectrum(rng.normal(0.0, sigma, 20000), fs)
    assert freq[-1] == pytest.approx(fs / 2)
    assert np.median(asd[1:]) == pytest.approx(np.sqrt(2 * sigma**2 / fs), rel=0.05)


def test_measured_data_campaigns_get_a_fitted_figure_worst_channel_first(measured, tmp_path):
    campaign, d = measured
    [(label, fits)] = campaign_fits(campaign)
    assert label == str(d / "run.csv")
    chi2 = [f.chi2_per_sample for f in fits]
    assert chi2 == sorted(chi2, reverse=True)
    assert {f.name for f in fits} == set(campaign.channels)
    written = write_plots([campaign], [str(d / "fit.h5")], tmp_path)
    names = {p.name for p in written}
    assert "fitted_fit.png" in names, names
    image = read_png(tmp_path / "fitted_fit.png")
    assert image.shape[0] > 1000  # a row per channel


# ------------------------------------------------------------------------------------------ diagnose: before / after


@pytest.fixture(scope="module")
def diagnosed(tmp_path_factory):
    """A diagnosis of a car whose kf and cr are off their configured values (the loop frees them), with the steps
    its progress hook heard."""
    from vehid_cli.systems import diagnose_config

    d = tmp_path_factory.mktemp("diagnosed")
    truth = load_config(BASE_CONFIG, SHORT + ["vehicle.kf=54000", "vehicle.cr=2975", "noise.level=0.05"])
    VehicleSystem.write_simulation(truth, d / "kfcr.csv", seed=3)
    steps: list[tuple[str, int, int | None]] = []
    result = diagnose_config(BASE_CONFIG, SHORT, d / "kfcr.csv", progress=lambda *a: steps.append(a))
    return result, d, steps


def test_the_diagnosis_keeps_the_data_and_its_fits_are_the_models_at_the_estimates(diagnosed):
    from vehid_cli.identify.task import build_task
    from vehid_cli.io.measurement import read_measurement

    result, d, _ = diagnosed
    assert {"parameter:kf", "parameter:cr"} <= set(result.selected)
    data = read_measurement(d / "kfcr.csv")
    cfg = load_config(BASE_CONFIG, SHORT + ["identify.objective=wls", "noise.level=0", "simulation.integrator=rk4"])
    task = build_task(cfg, d / "kfcr.csv")  # the loop integrates by RK4
    exp = task.experiment
    for report in (result.before, result.after):
        an = report.analysis
        values = {n: [v] for n, v in zip(report.names, report.x, strict=True)}
        model = exp.read(exp.simulate(values))  # the car at this fit's estimates, simulated apart from the loop
        for j, name in enumerate(an.channels):
            family, k = name[:-1], int(name[-1]) - 1
            np.testing.assert_allclose(an.measured[:, j], getattr(data, family)[:, k])
            np.testing.assert_allclose(an.fitted[:, j], model[family][0, :, k], rtol=1e-6, atol=1e-9)
        assert an.units == tuple("m/s^2" if n.startswith("acc") else "m" for n in an.channels)


def test_the_diagnosis_figure_orders_channels_worst_first(diagnosed, tmp_path):
    from vehid_cli.report.diagnose_plots import channel_order, plot_diagnosis

    result, _, _ = diagnosed
    an = result.before.analysis
    order = channel_order(an)
    assert sorted(order) == list(range(len(an.channels)))
    assert list(an.chi2_channel[order]) == sorted(an.chi2_channel, reverse=True)
    paths = plot_diagnosis(result, tmp_path, "kfcr")
    assert tmp_path / "kfcr-channels.png" in paths
    read_png(tmp_path / "kfcr-channels.png")


def test_the_loop_reports_its_steps_through_the_hook(diagnosed):
    result, _, steps = diagnosed
    assert steps[:2] == [("declared fit", 0, 1), ("declared fit", 1, 1)]
    first = [s for s in steps if s[0] == "round 1 candidates"]
    n = len(result.rounds[0])  # from 0 to every test done, never back (tests the score settles count at once)
    done = [k for _, k, _ in first]
    assert done[0] == 0 and done[-1] == n and all(t == n for _, _, t in first)
    assert all(np.diff(done) > 0), done
    refits = [s for s in steps if "re-fit" in s[0]]
    assert len(refits) >= 2 * len(result.steps) and refits[::2] == [(s, 0, 1) for s, _, _ in refits[1::2]]


def test_a_data_file_changed_since_the_fit_is_named_not_drawn_against(measured, tmp_path):
    from tests.conftest import cli

    _, d = measured
    data = tmp_path / "run.csv"
    data.write_bytes((d / "run.csv").read_bytes())
    write_campaign_h5(tmp_path / "fit.h5", run_campaign(load_config(BASE_CONFIG, FIT), data, jobs=1))
    with data.open("a") as fh:
        fh.write("# edited after the fit\n")
    res = cli("report", tmp_path / "fit.h5", "--plots", tmp_path / "figs")
    assert res.exit_code == 2 and f"{data}: has changed since the campaign was fitted" in res.stderr, res.output
    res = cli("report", tmp_path / "fit.h5", "--html", tmp_path / "page.html")  # the page still goes out
    assert res.exit_code == 0, res.output
    page = (tmp_path / "page.html").read_text(encoding="utf-8")
    assert "no figures: " in page and "has changed since the campaign was fitted" in page and "<table" in page
