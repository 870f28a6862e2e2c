"""Sweeps: planning, sharding for job arrays, skipping finished campaigns."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from tests.conftest import BASE_CONFIG, ROOT, vehid
from vehid_cli.campaign.results import read_campaign_h5
from vehid_cli.campaign.sweep import parse_shard, parse_vary, plan_sweep, split_top_level
from vehid_cli.core.errors import InputError
from vehid_cli.core.locking import exclusive

SMALL = [
    "simulation.duration=1.5", "simulation.dt=0.002", "identify.runs=2",
    "identify.algorithm.population=6", "identify.algorithm.iterations=3",
]  # fmt: skip


def test_split_respects_brackets():
    assert split_top_level("a, [1, 2], {x: 1, y: 2},b") == ["a", "[1, 2]", "{x: 1, y: 2}", "b"]


def test_plan_is_the_cartesian_product(tmp_path):
    vary = parse_vary(["identify.algorithm.name=ga,cpso,abc", "noise.level=0.1,0.2"])
    planned = plan_sweep(BASE_CONFIG, SMALL, vary, tmp_path)
    assert len(planned) == 6
    assert {(p.config.identify.algorithm.name, p.config.noise.level) for p in planned} == {
        (a, n) for a in ("ga", "cpso", "abc") for n in (0.1, 0.2)
    }
    assert len({p.path for p in planned}) == 6
    assert len({p.config.digest() for p in planned}) == 6


@pytest.mark.parametrize("bad", ["noise.level", "=1,2", "noise.level=", "noise.level=0.1,,0.2"])
def test_bad_vary(bad):
    with pytest.raises(InputError, match="--vary"):
        parse_vary([bad])


def test_bad_value_fails_before_anything_runs(tmp_path):
    with pytest.raises(InputError, match="identify.algorithm.name"):
        plan_sweep(BASE_CONFIG, SMALL, parse_vary(["identify.algorithm.name=ga,pso"]), tmp_path)


@pytest.mark.parametrize("bad", ["0/2", "3/2", "1-2", "a/b"])
def test_bad_shard(bad):
    with pytest.raises(InputError, match="--shard"):
        parse_shard(bad)


def test_shards_cover_the_sweep_and_reruns_skip(tmp_path):
    sets = [x for s in SMALL for x in ("--set", s)]
    args = ["sweep", BASE_CONFIG, "--vary", "identify.algorithm.name=de,cpso", "--vary", "noise.level=0.1,0.2"]
    args += sets + ["-o", tmp_path, "--jobs", "1"]
    for shard in ("1/2", "2/2"):
        res = vehid(*args, "--shard", shard)
        assert res.returncode == 0, res.stderr
        assert "2 campaign(s) run" in res.stdout
    files = sorted(p.name for p in tmp_path.glob("*.h5"))
    assert files == [f"name-{a}_level-{n}.h5" for a in ("cpso", "de") for n in ("0.1", "0.2")]
    index = {r["file"]: r for r in csv.DictReader(io.StringIO((tmp_path / "index.csv").read_text()))}
    assert sorted(index) == files
    for name in files:  # each file holds the campaign its name and its index row say
        algorithm, level = name.removesuffix(".h5").split("_")
        config = read_campaign_h5(tmp_path / name).config
        assert (config.identify.algorithm.name, config.noise.level) == (algorithm[5:], float(level[6:]))
        assert (config.identify.runs, config.simulation.duration) == (2, 1.5)
        row = index[name]
        assert row["overrides"] == f"identify.algorithm.name={algorithm[5:]} noise.level={level[6:]}"
        assert row["config_sha256"] == config.digest()
    again = vehid(*args)
    assert "0 campaign(s) run, 4 up to date" in again.stdout
    changed = vehid(*args, "--set", "identify.seed=9")  # files of another config: refused before any work
    assert changed.returncode == 2 and "4 campaign file(s) here hold other configs" in changed.stderr
    assert "identify.seed: 2015 in the file, 9 now" in changed.stderr
    forced = vehid(*args, "--set", "identify.seed=9", "--force")
    assert "4 campaign(s) run" in forced.stdout


def test_a_kill_during_a_campaigns_clean_up_leaves_nothing_after_the_rerun(tmp_path):
    """SIGKILL between a campaign file's write and its clean-up leaves its checkpoint and lock file beside it; the
    rerun skips the finished campaign and removes them (not while another process holds the lock)."""
    sets = [x for s in SMALL for x in ("--set", s)]
    args = ["sweep", BASE_CONFIG, "--vary", "noise.level=0.1,0.2"] + sets + ["-o", tmp_path, "--jobs", "1"]
    assert vehid(*args).returncode == 0
    done = {p.name: p.read_bytes() for p in tmp_path.glob("*.h5")}
    stale = tmp_path / "level-0.1.h5.partial"
    stale.mkdir()
    (stale / "campaign.json").write_text('{"key": "of the finished campaign"}')
    (tmp_path / ".level-0.2.h5.lock").touch()
    with exclusive(tmp_path / "level-0.1.h5"):  # another process holds it: its checkpoint is its own business
        held = vehid(*args)
    assert held.returncode == 0 and "0 campaign(s) run, 2 up to date" in held.stdout
    assert stale.is_dir() and not (tmp_path / ".level-0.2.h5.lock").exists()
    again = vehid(*args)
    assert again.returncode == 0 and "0 campaign(s) run, 2 up to date" in again.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["index.csv", "level-0.1.h5", "level-0.2.h5"]
    assert {p.name: p.read_bytes() for p in tmp_path.glob("*.h5")} == done
    (tmp_path / ".level-0.1.h5.lock").mkdir()  # not vehid's to remove: left, and the finished campaign still done
    odd = vehid(*args)
    assert odd.returncode == 0 and "0 campaign(s) run, 2 up to date" in odd.stdout
    assert (tmp_path / ".level-0.1.h5.lock").is_dir()


def test_sweep_of_a_damper_config_runs_and_reports_like_the_car(tmp_path):
    """Was an AttributeError (exit 1) after writing index.csv: a damper sweep now runs through the one pipeline,
    one campaign file per setting (system = damper), and `report` reads the directory."""
    config = ROOT / "configs" / "dampers" / "synthetic_force_map_steps.yaml"
    out = tmp_path / "sweep"
    args = ["sweep", config, "--vary", "identify.seed=1,2", "-o", out, "--runs", "2", "--jobs", "2"]
    res = vehid(*args, "--set", "identify.budget=60")
    assert res.returncode == 0, res.stderr
    assert "2 campaign(s) run" in res.stdout
    estimates = []
    for name in ("seed-1.h5", "seed-2.h5"):
        with h5py.File(out / name) as h5:
            assert h5.attrs["system"] == "damper" and h5.attrs["runs"] == 2
            assert json.loads(h5.attrs["sweep_vary"]) == ["identify.seed"]
            estimates.append(h5["runs/estimate"][()])
    assert not np.array_equal(*estimates)  # the seeds drew different noise
    again = vehid(*args, "--set", "identify.budget=60")
    assert "0 campaign(s) run, 2 up to date" in again.stdout
    report = vehid("report", out, "--format", "csv")
    assert report.returncode == 0, report.stderr
    rows = list(csv.DictReader(io.StringIO(report.stdout)))
    assert {Path(r["file"]).name for r in rows} == {"seed-1.h5", "seed-2.h5"}


@pytest.mark.parametrize(
    "text, fragment",
    [(b"\xff\xfe garbage", "cannot read"), (b"index,file\n0,a.h5\n", "no overrides"),
     (b"index,file,overrides,config_sha256\n0,../../etc/passwd.h5,x,y\n", "not a campaign file"),
     (b"index,file,overrides,config_sha256\n0,a.h5\n", "no overrides"),
     (b"index,file,overrides,config_sha256\n0,a.h5,x,y,z\n", "more cells")],
    ids=["not UTF-8", "columns missing", "a path", "a short row", "a long row"],
)  # fmt: skip
def test_a_damaged_sweep_index_is_refused_naming_the_line(tmp_path, text, fragment):
    from vehid_cli.campaign.sweep import read_index

    (tmp_path / "index.csv").write_bytes(text)
    with pytest.raises(InputError, match=fragment) as caught:
        read_index(tmp_path / "index.csv")
    assert "index.csv" in str(caught.value)
