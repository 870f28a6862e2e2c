"""What a car's `vehid diagnose` pays around its loop (issue 26): the modules it imports (not the other systems', the
campaign reader's or h5py), the registries that still know every system when asked, and the validation J read from
a fit's own residual vector (CarLoop.points) equal to the one simulated again."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from vehid_cli.config import load_config
from vehid_cli.identify.task import build_task
from vehid_cli.systems.vehicle.diagnosis import CarLoop, prepare_config, validation_split

ROOT = Path(__file__).resolve().parents[1]
BASE = ROOT / "configs" / "gokdag2015" / "base.yaml"
NOISE = ["identify.objective=wls", "noise.level=0.03", "identify.truth=config"]


def fresh(code: str) -> str:
    """stdout of `code` in a fresh interpreter on this source tree."""
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True).stdout


def test_a_cars_diagnosis_imports_no_other_system_no_campaign_reader_and_no_h5py():
    loaded = json.loads(fresh(
        "import json, sys; import vehid_cli.cli.app, vehid_cli.cli.diagnose, vehid_cli.systems, "
        "vehid_cli.systems.vehicle.diagnosis, vehid_cli.report.diagnosis; print(json.dumps(sorted(sys.modules)))"
    ))  # fmt: skip
    assert "vehid_cli.systems.vehicle.diagnosis" in loaded  # the probe imported what a diagnosis does
    unwanted = ("h5py", "vehid_cli.campaign.results", "vehid_cli.report.campaigns", "vehid_cli.systems.damper",
                "vehid_cli.systems.half_car", "vehid_cli.systems.quarter_car", "vehid_cli.config.damper",
                "vehid_cli.config.half_car", "vehid_cli.config.quarter_car", "vehid_cli.models.damper")  # fmt: skip
    assert [m for m in unwanted if m in loaded] == []


def test_the_registries_still_know_every_system_and_validate_a_damper_config():
    out = fresh(
        "from vehid_cli.config import CONFIGS, load_config; from vehid_cli.systems import SYSTEMS, system_class; "
        "c = load_config('configs/dampers/mr_bingham.yaml'); "
        "print(sorted(CONFIGS), sorted(SYSTEMS), type(c).__name__, system_class(c).__name__)"
    )
    assert out.split("] ")[0] + "]" == str(sorted(["vehicle", "damper", "quarter_car", "half_car"]))
    assert out.split()[-2:] == ["DamperConfig", "DamperSystem"]


def test_the_validation_j_from_a_fits_own_point_equals_the_one_simulated_again():
    truth = build_task(prepare_config(load_config(BASE, [*NOISE, "vehicle.kf=54000"])))
    task = dataclasses.replace(build_task(prepare_config(load_config(BASE, NOISE))), sigma=truth.sigma)
    ref = truth.reference(0)
    split = validation_split(task.config, task, ref, ["run.csv"], None)
    names = task.names
    remembering = CarLoop(task, ref, split, {"limits": {}, "start": {}}, ("run.csv",))
    plain = CarLoop(task, ref, split, {"limits": {}, "start": {}}, ("run.csv",))
    x = task.nominal * 1.01
    problem, _ = remembering.problem_for(names)
    problem.cost(np.vstack([x, task.nominal]))  # a population is not remembered: only single points
    assert remembering.points.get(names, x) is None
    problem.cost(x[None, :])  # a fit's single point
    assert remembering.points.get(names, x) is not None
    assert remembering.points.get(names, task.nominal) is None
    got = remembering.validation_J(names, x)[0]
    again = plain.validation_J(names, x)[0]  # nothing remembered: the held-out blocks simulated again
    assert plain.points.get(names, x) is None
    assert got == again  # bit for bit
    assert got != plain.validation_J(names, task.nominal)[0]


def test_linear_for_gives_normal_equations_where_the_twins_jacobian_is_too_long(monkeypatch):
    """An objective whose Jacobian is too long to hold carries its normal sums, no linearisation: linear_for offers
    them (Levenberg–Marquardt runs on them), and the score screening's basis, which needs the Jacobian itself, falls
    back to differences instead of calling the missing linearisation (score.fitted_basis called it once: the README's
    four-post rig crashed)."""
    from vehid_cli.diagnose.score import fitted_basis
    from vehid_cli.optimizers import lsq
    from vehid_cli.systems.vehicle.diagnosis import exact_twin

    task = build_task(prepare_config(load_config(BASE, NOISE)))
    ref = task.reference(0)
    split = validation_split(task.config, task, ref, ["run.csv"], None)
    car = CarLoop(task, ref, split, {"limits": {}, "start": {}}, ("run.csv",), twin=exact_twin(task))
    linear = car.linear_for(task.names)
    assert linear is not None and linear.linearised is not None
    monkeypatch.setattr(lsq, "LONG_JACOBIAN_BYTES", 1)  # every Jacobian "too long": normal sums only
    linear = car.linear_for(task.names)
    assert linear is not None and linear.linearised is None and linear.normal is not None
    problem = car.problem_for(task.names)[0]
    free = np.ones(task.dim, dtype=bool)
    basis = fitted_basis(problem, task.nominal, free, linear)
    assert basis is not None and np.all(np.isfinite(basis))


def test_the_command_line_freezes_what_is_alive_on_its_way_out_and_still_writes_its_outputs(tmp_path):
    """cli.app.run freezes every live object when a command ends (gc.freeze: the shutdown does not collect and free
    them one by one, 0.3-0.4 s after each command): seen by an exit hook registered before it, which runs after it;
    the command's own output is complete. Without the freeze the count is 0 and this fails."""
    out = tmp_path / "simulated.csv"
    code = (
        "import atexit, gc, sys; atexit.register(lambda: print('frozen', gc.get_freeze_count())); "
        "from vehid_cli.cli.app import run; "
        f"sys.argv = ['vehid', 'simulate', {str(BASE)!r}, '-o', {str(out)!r}, '--set', 'simulation.duration=0.5']; "
        "run()"
    )
    res = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    frozen = int(res.stdout.split("frozen")[-1])
    assert frozen > 10_000  # numpy, numba, typer, pydantic and the package itself
    assert len(out.read_text().splitlines()) > 400  # 0.5 s at the config's rate, every row written


def test_the_command_line_collects_cycles_less_often(tmp_path):
    """cli.app.run collects the youngest generation every GC_YOUNG allocations (CPython's 700 collected a 3 s
    diagnosis ~300 times, two of them full passes over the library's heap): the collections a short simulation
    makes after the CLI's import, counted at exit, are a fifth of what the default thresholds make of it at most."""
    out = tmp_path / "simulated.csv"

    def collections(extra: str) -> int:
        code = (
            "import atexit, gc, sys; from vehid_cli.cli import app; n0 = gc.get_stats()[0]['collections']; "
            f"atexit.register(lambda: print('gen0', gc.get_stats()[0]['collections'] - n0)); {extra}"
            f"sys.argv = ['vehid', 'simulate', {str(BASE)!r}, '-o', {str(out)!r}, '--set', 'simulation.duration=0.5']; "
            "app.run()"
        )
        res = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
        assert res.returncode == 0, res.stderr
        return int(res.stdout.split("gen0")[-1])

    default = collections("app.GC_YOUNG = gc.get_threshold()[0]; ")
    assert collections("") * 5 < default, default
