"""vehid diagnose on a damper test bench (issue 6, items 3 and 5): the bench effects against closed forms,
the loop on synthetic bench data with a known missing effect, and on the real friction damper."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy import signal
from typer.testing import CliRunner

from tests.conftest import needs_shared_data_of, read_png
from vehid_cli.cli.app import app
from vehid_cli.config import load_config
from vehid_cli.models.bench import sine
from vehid_cli.models.damper import default_values
from vehid_cli.systems.damper.diagnosis import diagnose_damper
from vehid_cli.systems.damper.fit import DamperSpec

ROOT = Path(__file__).resolve().parents[1]
BRFD = ROOT / "configs" / "dampers" / "brfd_bingham.yaml"

BINGHAM = {"k1": 1000.0, "x0": -0.15, "c0": 2000.0, "fc": 100.0, "v_eps": 0.01}


def _config(tmp_path: Path, name: str, effects: dict, noise: float = 0.02, **bench) -> Path:
    """A Bingham damper on a 2 Hz sine bench, with `effects` in the truth (the diagnosis config omits them)."""
    doc = {
        "system": "damper",
        "damper": {"model": "bingham", "parameters": BINGHAM, "effects": effects},
        "bench": {"excitation": "sine", "amplitude": 0.01, "frequency": 2.0, "cycles": 4, "dt": 0.001, **bench},
        "noise": {"level": noise},
        "identify": {"unknowns": ["k1", "x0", "c0", "fc", "v_eps"], "bounds": [0.01, 100.0],
                     "limits": {"x0": [-1.0, 1.0]}, "budget": 600},
    }  # fmt: skip
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(doc))
    return path


def _simulate(tmp_path: Path, name: str, effects: dict, **kw) -> tuple[Path, Path]:
    """(declared config without the effects, data file simulated with them)."""
    truth = _config(tmp_path, name + "_truth", effects, **kw)
    data = tmp_path / f"{name}.csv"
    result = CliRunner().invoke(app, ["simulate", str(truth), "-o", str(data)])
    assert result.exit_code == 0, result.output
    return _config(tmp_path, name, {}, **kw), data


# ------------------------------------------------------------------------------------------ bench effects


def test_bench_effects_at_zero_strength_are_the_plain_model():
    h = sine(0.02, 1.0, 3, 1e-3, 0.0)
    vals = {**default_values("bingham"), **BINGHAM, "gap": 0.002}
    plain = DamperSpec("bingham", vals).simulate(h, 2)
    zero = {"damper_lag.T": 0.0, "hysteresis.alpha": 0.0, "asymmetric_damping.dc": 0.0, "coulomb_friction.Fc": 0.0}
    spec = DamperSpec("bingham", {**vals, **zero}, effects=tuple(k.split(".")[0] for k in zero))
    np.testing.assert_array_equal(spec.simulate(h, 2), plain)


def test_bench_lag_is_a_first_order_filter_of_the_damper_force():
    """A viscous damper through damper_lag = c0 v filtered by 1 / (T s + 1) (scipy.signal.lsim, exact for FOH)."""
    h = sine(0.02, 3.0, 3, 1e-3, 0.0)
    c0, T = 1500.0, 0.02
    vals = {**default_values("viscous"), "c0": c0, "damper_lag.T": T}
    lagged = DamperSpec("viscous", vals, effects=("damper_lag",)).simulate(h, 4)
    _, ref, _ = signal.lsim(([1.0], [T, 1.0]), c0 * h.v, h.t, X0=[c0 * h.v[0] * T], interp=True)
    assert np.max(np.abs(lagged - ref)) < 1e-5 * np.max(np.abs(ref))


def test_bench_hysteresis_saturates_at_its_closed_form_level():
    """Bouc-Wen n = 2: on a long stroke z saturates at sqrt(A / (beta + gamma)); the force there is alpha z_sat."""
    h = sine(0.05, 0.5, 2, 1e-3, 0.0)
    alpha, beta, gamma = 1e5, 1e5, 1.5e5
    vals = {
        **default_values("gas_spring"),
        "hysteresis.alpha": alpha,
        "hysteresis.beta": beta,
        "hysteresis.gamma": gamma,
    }
    f = DamperSpec("gas_spring", vals, effects=("hysteresis",)).simulate(h, 2)
    assert np.max(f) == pytest.approx(alpha * np.sqrt(1.0 / (beta + gamma)), rel=1e-3)


def test_damper_config_effects_are_validated(tmp_path):
    bad = _config(tmp_path, "bad", {"hysteresis": {"alfa": 1.0}})
    result = CliRunner().invoke(app, ["simulate", str(bad), "-o", str(tmp_path / "x.csv")])
    assert result.exit_code == 2
    assert "damper.effects.hysteresis.alfa" in result.output and "alpha" in result.output
    bad = _config(tmp_path, "bad2", {"backlash": {"gap": 0.001}})
    result = CliRunner().invoke(app, ["simulate", str(bad), "-o", str(tmp_path / "x.csv")])
    assert result.exit_code == 2 and "gap" in result.output


# ------------------------------------------------------------------------------------------ the loop


@pytest.mark.parametrize(
    ("effect", "params"),
    [("hysteresis", {"alpha": 5e4, "beta": 2e5, "gamma": 2e5}), ("damper_lag", {"T": 0.008})],
)
def test_the_missing_bench_effect_is_found_and_j_reaches_the_noise(tmp_path, effect, params):
    declared, data = _simulate(tmp_path, effect, {effect: params})
    cfg = load_config(declared)
    d = diagnose_damper(cfg, data)
    assert d.quality.ok
    assert d.rounds[0][0].effect == effect
    assert d.selected[:1] == (effect,)
    noise_J = 0.02**2 / (1 + 0.02**2)  # Eq. 7 of pure 2 % noise
    assert d.after.J < 1.5 * noise_J < d.before.J / 3
    assert d.after.validation_J < d.before.validation_J
    assert d.to_json()["before"]["validation_J"] is None  # held-out blocks, not a --validate file


def test_no_bench_effect_selects_nothing(tmp_path):
    declared, data = _simulate(tmp_path, "plain", {})
    d = diagnose_damper(load_config(declared), data)
    assert d.selected == ()
    assert d.quality.ok
    assert d.verdict.startswith("adequate")


def test_one_stroke_is_too_few_to_claim_anything(tmp_path):
    """Issue 6, item 5: half a cycle of data with hysteresis in it: no effect claimed, and the answer says why."""
    declared, data = _simulate(tmp_path, "short", {"hysteresis": {"alpha": 5e4, "beta": 2e5, "gamma": 2e5}}, cycles=0.6)
    d = diagnose_damper(load_config(declared), data, candidate_budget=60)
    assert d.selected == ()
    assert not d.quality.ok
    assert any("too short" in r for r in d.quality.reasons)
    assert any("strokes" in r for r in d.quality.reasons)
    assert d.verdict.startswith("inconclusive")


def test_noisy_bench_data_claims_nothing(tmp_path):
    declared, data = _simulate(tmp_path, "noisy", {"hysteresis": {"alpha": 5e4, "beta": 2e5, "gamma": 2e5}}, noise=1.0)
    d = diagnose_damper(load_config(declared), data, candidate_budget=60)
    assert d.selected == ()
    assert any("too noisy" in r for r in d.quality.reasons)


def test_real_friction_damper_cli(tmp_path):
    """Issue 6, item 3 (friction damper): the CLI adds hysteresis, the held-out J falls, figures are written."""
    needs_shared_data_of(BRFD)
    out = tmp_path / "brfd.json"
    result = CliRunner().invoke(app, ["diagnose", str(BRFD), "--json", str(out), "--plots", str(tmp_path / "fig")])
    assert result.exit_code == 0, result.output
    doc = json.loads(out.read_text())
    assert doc["system"] == "damper"
    assert doc["selected"][0] == "hysteresis"
    step = doc["steps"][0]
    assert step["J_after"] < 0.5 * step["J_before"]
    assert step["validation_J_after"] < 0.5 * step["validation_J_before"]
    assert set(doc["after"]["validation_J_per_file"]) == {
        "dataset-2_char_0.5Hz36lbtension0.5amplitude", "dataset-2_char_0.5Hz36lbtension1.5amplitude"
    }  # fmt: skip
    for kind in ("residual", "fingerprint", "spectrum"):
        read_png(tmp_path / "fig" / f"brfd_bingham-{kind}.png")


MR = ROOT / "configs" / "dampers" / "mr_bingham.yaml"


@pytest.mark.parametrize("config", [BRFD, MR], ids=["friction", "mr"])
def test_real_damper_claims_are_real(config, tmp_path):
    """Issue 11, acceptance 4: on the shared real dampers every claimed effect has a strength interval that
    excludes zero and lowers J on every held-out run; the verdict says whether the residual is at the noise.
    Issue 25, acceptance 3: when it is not, the force the model misses is shown as a law of velocity and
    displacement (JSON `unexplained`, a figure); on the MR damper it lowers the held-out J below the final
    parametric model's on every held-out run."""
    d = diagnose_damper(load_config(needs_shared_data_of(config)))
    check_bench_law(d, config, tmp_path)
    assert d.selected, d.notes
    before = d.before.validation_per_file
    assert before and len(before) >= 2
    for step in d.steps:
        after = step.validation_per_file_after
        assert all(after[k] < before[k] for k in before), (step.effect, before, after)
        before = after
    names = list(d.after.names)
    for effect in (e for e in d.selected if not e.startswith("parameter:")):
        own = {"gas_spring": "k1", "backlash": "gap"}  # the damper's own gas force and play
        strengths = [n for n in names if n.startswith(effect + ".")][:1] or [own[effect]]
        for n in strengths:  # the first of an effect's parameters is its strength
            j = names.index(n)
            assert abs(d.after.x[j]) > d.after.ci[j], (n, d.after.x[j], d.after.ci[j])
    assert d.verdict.split(":")[0] in ("found", "incomplete")
    assert d.verdict.startswith("incomplete") == (d.after.chi2_per_sample > d.chi2_limit)


def check_bench_law(d, config, tmp_path):
    """The bench's non-parametric law of an incomplete diagnosis: in the JSON beside the parametric held-out J (the
    final model's, recomputed independently here from the per-run values), in the verdict and in a figure."""
    if not d.verdict.startswith("incomplete"):
        return
    law = d.unexplained
    assert law is not None and law.significant
    out = d.to_json()["unexplained"]
    assert out["kind"] == "bench" and set(out["curves"]) >= {"velocity"}
    per = d.after.validation_per_file
    assert set(out["validation_J_per_file"]) == set(per)
    for k, v in out["validation_J_per_file"].items():
        assert v["parametric"] == pytest.approx(per[k], rel=1e-9)
    assert out["validation_J_parametric"] == pytest.approx(d.after.validation_J, rel=1e-9)
    assert "the unexplained damper force" in d.verdict
    if config == MR:
        assert law.lowers_validation, out["validation_J_per_file"]
        assert out["validation_J_non_parametric"] < 0.9 * out["validation_J_parametric"]
    from vehid_cli.report.diagnose_plots import plot_unexplained

    read_png(plot_unexplained(law, tmp_path / "law.png"))
