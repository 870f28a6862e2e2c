"""Fingerprints of the numbers vehid produces on a few fixed cases: the paper's campaigns (ABC/f2 and hybrid/wls),
the bound, a damper campaign, the nonlinear car with every effect, the bench effects and a diagnosis.

`tests/test_numbers.py` recomputes them and compares them bit for bit with `tests/golden/numbers.json`, which was
written by `python -m tests.golden` at the commit before the package was reorganised ("One home per concept"): a
move must not change a single bit. Re-record only for a change that is meant to alter the numbers, and say so in
its commit.
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = ROOT / "tests" / "golden" / "numbers.json"
BASE = ROOT / "configs" / "gokdag2015" / "base.yaml"
DAMPER = ROOT / "configs" / "dampers" / "synthetic_bingham.yaml"
ASYM = ROOT / "configs" / "effects" / "asymmetric_damping.yaml"


def digest(values) -> str:
    """SHA-256 of an array's float64 bytes (C order): equal digests, equal numbers bit for bit."""
    a = np.ascontiguousarray(np.asarray(values, dtype=float))
    return hashlib.sha256(repr(a.shape).encode() + a.tobytes()).hexdigest()


def exact(values) -> list[str]:
    """Floats as hex strings (exact, readable in a diff)."""
    return [float(v).hex() for v in np.ravel(np.asarray(values, dtype=float))]


def campaign_numbers(campaign) -> dict:
    recs = campaign.records
    return {
        "estimates": exact([r.estimate for r in recs]),
        "costs": exact([r.cost for r in recs]),
        "evaluations": [int(r.evaluations) for r in recs],
        "chi2": exact([r.chi2 for r in recs]),
        "fisher": digest(campaign.bound.fisher),
        "re_sd_percent": exact(campaign.bound.re_sd_percent),
    }


def compute() -> dict:
    """Every fingerprint, computed now."""
    from vehid_cli.campaign.runner import run_campaign
    from vehid_cli.config import load_config
    from vehid_cli.systems.vehicle.diagnosis import diagnose

    out: dict = {}
    paper = load_config(BASE, ["identify.runs=2", "identify.algorithm.iterations=10"])
    out["paper_abc_f2"] = campaign_numbers(run_campaign(paper, jobs=1))
    wls = load_config(
        BASE, ["identify.runs=2", "identify.algorithm.name=hybrid", "identify.objective=wls", "sensors=acc"]
    )
    out["paper_hybrid_wls"] = campaign_numbers(run_campaign(wls, jobs=1))
    damper = load_config(DAMPER, ["identify.runs=2", "identify.budget=120"])
    out["damper_bingham"] = campaign_numbers(run_campaign(damper, jobs=1))
    out["nonlinear_car"] = nonlinear_car(load_config)
    out["bench_effects"] = digest(bench_forces(load_config))
    out["diagnose_asymmetric"] = diagnose_numbers(diagnose, load_config)
    return out


EVERY_EFFECT = {
    "asymmetric_damping": {"dc_f": 800.0, "dc_r": -600.0, "v_eps": 0.03},
    "coulomb_friction": {"Fc_f": 90.0, "Fc_r": 120.0, "v_eps": 0.02},
    "progressive_spring": {"k3_f": 4e6, "k3_r": 6e6},
    "tyre_damping": {"ct_f": 150.0, "ct_r": 200.0},
    "hysteresis": {"alpha_f": 20000.0, "alpha_r": 30000.0, "beta": 2e4, "gamma": 3e4, "A": 1.0},
    "gas_spring": {"F0_f": 600.0, "F0_r": 800.0, "L": 0.12, "kappa": 1.3},
    "backlash": {"gap_f": 0.002, "gap_r": 0.003, "k_contact": 2e6},
    "damper_lag": {"T_f": 0.004, "T_r": 0.006},
}


def nonlinear_car(load_config) -> dict:
    """The car with every library effect at once through both integrators: each output channel's digest."""
    import yaml

    raw = yaml.safe_load(BASE.read_text())
    raw["vehicle"]["effects"] = EVERY_EFFECT
    raw["simulation"]["duration"] = 1.0
    out = {}
    for method in ("rk4", "newmark"):
        raw["simulation"]["integrator"] = method
        path = ROOT / "tests" / "golden" / f".every-effect-{method}.yaml"
        path.write_text(yaml.safe_dump(raw))
        try:
            cfg = load_config(path)
        finally:
            path.unlink()
        from vehid_cli.identify.experiment import build_experiment

        outputs = build_experiment(cfg).outputs()
        out.update({f"{method}:{k}": digest(v) for k, v in outputs.items()})
    return out


def bench_forces(load_config):
    """A Bouc-Wen damper with every bench effect around it, on a sine: the force."""
    from vehid_cli.models.damper import default_values
    from vehid_cli.systems.damper.bench import bench_history
    from vehid_cli.systems.damper.fit import DamperSpec

    cfg = load_config(DAMPER)
    history = bench_history(cfg)
    spec = DamperSpec(
        "bouc_wen",
        default_values("bouc_wen")
        | {"k1": 1000.0, "x0": -0.05, "c0": 2000.0, "k0": 100.0, "c1": 10000.0, "alpha": 500.0, "beta": 1e5,
         "gamma": 1e5, "delta": 300.0, "gap": 0.001},
        (),
        ("asymmetric_damping", "coulomb_friction", "progressive_spring", "hysteresis", "damper_lag"),
    )  # fmt: skip
    values = {
        "asymmetric_damping.dc": 300.0, "asymmetric_damping.v_eps": 0.03, "coulomb_friction.Fc": 40.0,
        "coulomb_friction.v_eps": 0.01, "progressive_spring.k3": 1e6, "hysteresis.alpha": 5000.0,
        "hysteresis.beta": 2e4, "hysteresis.gamma": 2e4, "hysteresis.A": 1.0, "damper_lag.T": 0.003,
    }  # fmt: skip
    return spec.with_values(values).simulate(history, 4)


def diagnose_numbers(diagnose, load_config) -> dict:
    """A diagnosis of a simulated run with asymmetric damping in it (small budgets)."""
    import tempfile

    from vehid_cli.systems import write_simulation

    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "asym.csv"
        cfg = load_config(ASYM, ["simulation.duration=1.5", "noise.level=0.02"])
        write_simulation(cfg, data, 5)
        base = load_config(
            BASE,
            ["identify.objective=wls", "noise.level=0", "identify.truth=config", "identify.algorithm.name=hybrid",
             "identify.budget=600", "simulation.duration=1.5"],
        )  # fmt: skip
        d = diagnose(base, data, candidate_budget=40, refit_budget=200, analyse_residuals=False)
    return {
        "selected": list(d.selected),
        "before": exact(d.before.x),
        "after": exact(d.after.x),
        "after_names": list(d.after.names),
        "J": exact([d.before.J, d.after.J]),
        "candidates": [[r.effect, float(r.statistic).hex()] for r in d.rounds[0]] if d.rounds else [],
        "verdict": d.verdict.split(" (")[0],
    }


if __name__ == "__main__":
    numbers = compute()
    GOLDEN.parent.mkdir(exist_ok=True)
    GOLDEN.write_text(json.dumps(numbers, indent=1) + "\n")
    print(f"wrote {GOLDEN}", file=sys.stderr)
