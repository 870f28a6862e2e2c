"""`vehid design` for the rigs (issue 24): the quarter car's chirp band and force amplitude, the half car's bump speed
and height, scored by the rig's own Cramér–Rao bound. The designed test is held against a brute-force grid of the
bound (each point a config loaded with `--set`, the bound built directly), a free scale stops the design naming it,
and bad ranges exit 2 naming the key."""

from __future__ import annotations

import itertools
import json

import numpy as np
import pytest

from tests.conftest import ROOT, cli, sets
from vehid_cli.config import load_config
from vehid_cli.core.errors import InputError
from vehid_cli.systems import build_system

QUARTER = ROOT / "configs" / "quarter_car" / "lab_rig.yaml"
HALF = ROOT / "configs" / "half_car" / "pitch_plane.yaml"
SMALL = ["design.search.iterations=4", "design.search.population=8", "design.search.grid=7"]
QUARTER_SPACE = ["simulation.duration=6", "design.band=null", "design.amplitude=[0.001,0.003]",
                 "design.force_amplitude=[0.5,5]", "noise.sigma.disp=1e-4", "noise.sigma.acc=0.05"]  # fmt: skip


def nre(config, extra=()):
    return build_system(load_config(config, list(extra))).bound().nre_rms_percent


def test_the_designed_test_is_the_best_of_a_brute_force_grid_and_beats_the_configured(tmp_path):
    doc = tmp_path / "d.json"
    res = cli("design", QUARTER, *sets(QUARTER_SPACE + SMALL), "--jobs", 2, "--json", doc)
    assert res.exit_code == 0, res.output
    got = json.loads(doc.read_text())
    designed = got["designed"]["criterion"]
    # the truth: every point of a 7 x 7 grid of the two amplitudes, each a config of its own
    grid = {
        (a, f): nre(QUARTER, [*QUARTER_SPACE, f"road.chirp.amplitude={a}", f"road.force.amplitude={f}"])
        for a, f in itertools.product(np.linspace(0.001, 0.003, 7), np.linspace(0.5, 5, 7))
    }
    best = min(grid.values())
    assert designed <= best * (1 + 1e-6)
    assert designed >= 0.9 * best  # the grid's best is the design to within what the grid resolves
    assert designed <= got["configured"]["criterion"]
    assert got["configured"]["criterion"] == pytest.approx(nre(QUARTER, QUARTER_SPACE), rel=1e-9)
    # with absolute floors the largest amplitudes identify best: the design sits at the upper corner
    assert got["designed"]["values"]["road.force.amplitude"] == pytest.approx(5, rel=1e-6)


def test_a_quarter_car_without_a_force_design_names_the_free_scale():
    res = cli("design", QUARTER, *sets(["road.actuator_force=none", "design.force_amplitude=null", *SMALL]))
    assert res.exit_code == 2, res.output
    err = " ".join(res.stderr.split())
    assert "ms, mu, ks, kt, cs, ct scaled by one factor" in err
    assert "identify.unknowns" in err and "actuator force" in err


def test_the_lab_rig_designs_from_the_command_line_and_writes_a_config_that_reproduces_its_bound(tmp_path):
    saved, doc = tmp_path / "designed.yaml", tmp_path / "d.json"
    res = cli("design", QUARTER, *sets(["design.force_amplitude=[0.5,5]", "simulation.duration=6", *SMALL]),
              "-o", saved, "--json", doc)  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "road.chirp.f0 [Hz]" in res.stdout and "road.force.amplitude [N]" in res.stdout
    got = json.loads(doc.read_text())
    for key, value in got["designed"]["values"].items():
        lo, hi = next(v["range"] for v in got["variables"] if v["key"] == key)
        assert lo <= value <= hi
    assert nre(saved) == pytest.approx(got["designed"]["nre_bound_percent"], rel=1e-9)
    assert got["designed"]["criterion"] <= got["configured"]["criterion"]


def test_the_half_car_designs_its_bump_speed_and_height(tmp_path):
    doc = tmp_path / "d.json"
    space = ["simulation.duration=3", "design.bump_speed_kmh=[5,40]", "design.bump_height=[0.01,0.08]"]
    res = cli("design", HALF, *sets([*space, "design.search.iterations=2", "design.search.population=6",
                                     "design.search.grid=5"]), "--json", doc)  # fmt: skip
    assert res.exit_code == 0, res.output
    got = json.loads(doc.read_text())
    v = got["designed"]["values"]
    assert set(v) == {"road.speed_kmh", "road.bump.height"}
    truth = nre(HALF, [*space, f"road.speed_kmh={v['road.speed_kmh']}", f"road.bump.height={v['road.bump.height']}"])
    assert got["designed"]["nre_bound_percent"] == pytest.approx(truth, rel=1e-9)
    assert got["designed"]["criterion"] <= got["configured"]["criterion"]


@pytest.mark.parametrize(
    ("extra", "key"),
    [
        (["design.band=[20,5]"], "design.band"),
        (["road.actuator_force=none", "design.force_amplitude=[1,2]"], "design.force_amplitude"),
        (["design.bump_height=[0.01,0.02]"], "design.bump_height"),
        (["design.criterion=worst:zz"], "design.criterion"),
        (["design.criterion=best"], "design.criterion"),
        (["data.files=[run.csv]"], "data.files"),
        (["road.input=measured"], "road.input"),
    ],
)
def test_bad_design_ranges_exit_2_naming_the_key(extra, key):
    res = cli("design", QUARTER, *sets([*extra, *SMALL]))
    assert res.exit_code == 2, res.output
    assert key in res.stderr


def test_a_rig_without_a_design_section_names_it():
    cfg = load_config(QUARTER)
    assert cfg.design is None or cfg.design_variables()
    with pytest.raises(InputError) as exc:
        load_config(QUARTER, ["design=null"]).design_variables()
    assert exc.value.key == "design"


def test_the_designed_chirp_band_is_no_worse_than_any_band_of_a_grid_and_the_same_for_any_job_count(tmp_path):
    space = ["simulation.duration=6", "design.amplitude=null", "design.force_amplitude=null", "design.band=[1,25]"]
    docs = []
    for jobs in (1, 3):
        doc = tmp_path / f"d{jobs}.json"
        res = cli("design", QUARTER, *sets([*space, *SMALL]), "--jobs", jobs, "--json", doc)
        assert res.exit_code == 0, res.output
        docs.append(json.loads(doc.read_text()))
    assert docs[0]["designed"] == docs[1]["designed"]  # bit-identical for any number of jobs
    grid = [
        nre(QUARTER, [*space, f"road.chirp.f0={a}", f"road.chirp.f1={b}"])
        for a, b in itertools.product(np.linspace(1, 25, 7), np.linspace(1, 25, 7))
    ]
    assert docs[0]["designed"]["criterion"] <= min(grid) * (1 + 1e-6)
