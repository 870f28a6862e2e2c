"""Reports over sweeps (issue 7): shards of a job array merge into one report; campaigns of different experiments,
data or code are refused unless --allow-mixed."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import BASE_CONFIG, PAPER_CAR, SMALL, invoke, sets, small_config
from vehid_cli.campaign.results import read_campaign_h5, write_campaign_h5
from vehid_cli.campaign.runner import run_campaign
from vehid_cli.report.compare import Provenance, differences


def test_shards_into_one_directory_make_one_report(tmp_path):
    args = ["sweep", BASE_CONFIG, "--vary", "identify.algorithm.name=de,cpso,abc,ga", *sets(SMALL), "--runs", 2]
    args += ["--jobs", 1, "-o", tmp_path]
    code, out, err = invoke(*args, "--shard", "1/2")
    assert code == 0, err
    code, out, err = invoke("report", tmp_path, "--format", "csv")
    assert code == 0, err
    assert "index.csv lists 2 campaign(s) with no file yet (name-cpso.h5, name-ga.h5)" in err
    code, out, err = invoke(*args, "--shard", "2/2")
    assert code == 0, err
    code, md, err = invoke("report", tmp_path, "--format", "md")
    assert code == 0 and err == "", err
    assert md.count("**objective f2") == 1  # one table
    header = next(line for line in md.splitlines() if line.startswith("| parameter | unit | true"))
    assert all(f"{a} est ± 95 %" in header for a in ("de", "cpso", "abc", "ga"))
    code, text, err = invoke("report", tmp_path, "--format", "csv")
    rows = list(csv.DictReader(io.StringIO(text)))
    assert sorted({r["algorithm"] for r in rows}) == ["abc", "cpso", "de", "ga"] and len(rows) == 4 * 5


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("mixed")
    made = {
        "base": small_config("identify.runs=2"),
        "cpso": small_config("identify.runs=2", "identify.algorithm.name=cpso", "noise.level=0.2", "sensors=acc"),
        "stiffer": small_config("identify.runs=2", "vehicle.kf=50000"),
    }
    for name, cfg in made.items():
        write_campaign_h5(d / f"{name}.h5", run_campaign(cfg, jobs=1))
    return d


def md_tables(md: str) -> dict[str, dict[str, list[str]]]:
    """The markdown report's tables: {table title: {row label: cells}} (the header row under '')."""
    tables, title = {}, None
    for line in md.splitlines():
        if line.startswith("**"):
            title = line.strip("*")
            tables[title] = {}
        elif line.startswith("|") and not line.startswith("|---") and title is not None:
            cells = [c.strip() for c in line.strip("|").split("|")]
            tables[title][cells[0]] = cells[1:]
    return tables


def test_method_keys_may_differ(files):
    """DE (f2, both sensors, 10 %) and CPSO (acc only, 20 %) in one report: a table each, with the files' mean
    estimates, the paper's truth, and RE and NRE recomputed here from the printed estimates."""
    code, out, err = invoke("report", files / "base.h5", files / "cpso.h5", "--format", "md")
    assert code == 0 and err == "", err
    tables = md_tables(out)
    assert sorted(tables) == ["objective f2, sensors acc, Np = 20 %", "objective f2, sensors both, Np = 10 %"]
    for title, name in (
        ("objective f2, sensors both, Np = 10 %", "base"),
        ("objective f2, sensors acc, Np = 20 %", "cpso"),
    ):
        table = tables[title]
        algorithm = "cpso" if name == "cpso" else "de"
        assert table["parameter"] == ["unit", "true", f"{algorithm} est ± 95 %", f"{algorithm} RE %"]
        summary = read_campaign_h5(files / f"{name}.h5").summary
        res = []
        for j, parameter in enumerate(("m", "Ix", "Iy", "a1", "b1")):
            unit, true, est_pm, re = table[parameter]
            assert unit == {"m": "kg", "Ix": "kg m²", "Iy": "kg m²", "a1": "m", "b1": "m"}[parameter]
            est, half = est_pm.split(" ± ")
            # the last digit printed (rounded to two significant digits of the interval)
            last = 10.0 ** (-len(half.partition(".")[2]) if "." in half else np.floor(np.log10(float(half))) - 1)
            assert float(true) == PAPER_CAR[parameter]
            assert float(est) == pytest.approx(summary.mean[j], abs=0.5 * last * (1 + 1e-9))
            assert float(half) == pytest.approx(1.959963984540054 * summary.sd[j], abs=0.5 * last * (1 + 1e-9))
            assert float(re) == pytest.approx(100 * (summary.mean[j] - float(true)) / float(true), abs=2e-3)
            res.append(float(re))
        assert float(table["NRE of mean %"][-1]) == pytest.approx(np.linalg.norm(res), abs=5e-3)
        assert table["runs"][-1] == "2" and table["evaluations / run"][-1] == "40"


def test_another_car_is_refused_unless_allowed(files):
    code, out, err = invoke("report", files / "base.h5", files / "stiffer.h5")
    assert code == 2
    assert "not comparable" in err and "base.h5" in err and "stiffer.h5" in err
    assert "vehicle.kf (45000.0 vs 50000.0)" in err and "--allow-mixed" in err and "Traceback" not in err
    code, out, err = invoke("report", files, "--allow-mixed", "--format", "json")
    assert code == 0, err
    assert "note (--allow-mixed)" in err and "vehicle.kf" in err
    docs = json.loads(out)
    assert len(docs) == 3 and all(len(d["provenance"]["config_sha256"]) == 64 for d in docs)
    assert {d["provenance"]["git_commit"] for d in docs} and all("host" in d["provenance"] for d in docs)


def test_keys_a_sweep_varied_may_differ(tmp_path):
    code, out, err = invoke(
        "sweep", BASE_CONFIG, "--vary", "road.speed_kmh=20,30", *sets(SMALL), "--runs", 1, "--jobs", 1, "-o", tmp_path
    )
    assert code == 0, err
    code, out, err = invoke("report", tmp_path, "--format", "csv")
    assert code == 0 and err == "", err
    rows = list(csv.DictReader(io.StringIO(out)))
    assert sorted({Path(r["file"]).name for r in rows}) == ["speed_kmh-20.h5", "speed_kmh-30.h5"] and len(rows) == 10
    for name, speed in (("speed_kmh-20.h5", 20), ("speed_kmh-30.h5", 30)):
        assert read_campaign_h5(tmp_path / name).config.road.speed_kmh == speed
        mine = [r for r in rows if Path(r["file"]).name == name]
        assert [r["parameter"] for r in mine] == ["m", "Ix", "Iy", "a1", "b1"]
        re = []
        for r in mine:
            truth, mean = float(r["truth"]), float(r["mean"])
            assert truth == PAPER_CAR[r["parameter"]] and r["runs"] == "1"
            assert float(r["re_percent"]) == pytest.approx(100 * (mean - truth) / truth, rel=1e-9)
            re.append(float(r["re_percent"]))
        assert float(mine[0]["nre_percent"]) == pytest.approx(np.linalg.norm(re), rel=1e-9)
    assert rows[0]["mean"] != rows[5]["mean"]  # another speed, another road: another estimate


def test_another_numpy_is_refused(files, tmp_path, monkeypatch):
    import vehid_cli.campaign.results as results

    real = results.provenance
    monkeypatch.setattr(results, "provenance", lambda: dict(real(), numpy_version="1.0.0"))
    write_campaign_h5(tmp_path / "old.h5", run_campaign(small_config("identify.runs=2"), jobs=1))
    code, out, err = invoke("report", files / "base.h5", tmp_path / "old.h5")
    assert code == 2 and "numpy_version" in err and "1.0.0" in err, err


def test_data_files_must_match():
    def prov(data_file="", data_sha256="", **code):
        return Provenance("f.h5", {"a": 1}, "x", data_file, data_sha256, code, frozenset())

    assert differences(prov(), prov()) == []
    assert differences(prov("run.csv", "aa"), prov("run.csv", "aa")) == []
    assert differences(prov("run.csv", "aa"), prov("run.csv", "bb"))[0].startswith("data (run.csv (sha256 aa)")
    assert "simulated" in differences(prov(), prov("run.csv", "aa"))[0]
    assert differences(prov(git_commit="abc"), prov(git_commit="unknown")) == []
    assert differences(prov(vehid_version="0.1.0"), prov(vehid_version="0.2.0")) == ["vehid_version (0.1.0 vs 0.2.0)"]


def test_damper_models_on_one_bench_test_are_comparable_other_benches_are_not():
    """A damper campaign's model and identify keys are its method (models side by side on one test); its bench,
    data and noise are the experiment."""

    def prov(model, unknowns, amplitude=0.025, level=0.02, system="damper"):
        cfg = {
            "system": system, "damper": {"model": model, "parameters": {"c0": 1500.0}},
            "bench": {"excitation": "sine", "amplitude": amplitude}, "noise": {"level": level},
            "identify": {"unknowns": unknowns, "budget": 300},
        }  # fmt: skip
        return Provenance("f.h5", cfg, "x", "run.csv", "abc", {}, frozenset())

    assert differences(prov("bingham", ["c0", "fc"]), prov("bouc_wen", ["c0", "alpha"])) == []
    assert differences(prov("bingham", ["c0"]), prov("bingham", ["c0"], amplitude=0.05)) == [
        "bench.amplitude (0.025 vs 0.05)"
    ]
    car = differences(prov("bingham", ["c0"], system="vehicle"), prov("bouc_wen", ["c0"], system="vehicle"))
    assert car == ['damper.model ("bingham" vs "bouc_wen")']  # only dampers widen the method keys
