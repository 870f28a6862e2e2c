"""Campaigns: bit-identical for any --jobs, resumable after a kill, the SPEC JSON, and clear bad-input errors."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest
import yaml

from tests.conftest import (
    BASE_CONFIG,
    ROOT,
    SMALL,
    VEHICLE_DATA,
    assert_same_content,
    children,
    needs_shared,
    running,
    small_config,
    vehid,
)
from vehid_cli.campaign.results import read_campaign_h5, write_campaign_h5
from vehid_cli.campaign.runner import run_campaign, run_campaign_to_file
from vehid_cli.config import load_config


def test_same_seed_identical_results_for_any_jobs(tmp_path):
    cfg = small_config()
    for jobs in (1, 2):
        write_campaign_h5(tmp_path / f"j{jobs}.h5", run_campaign(cfg, jobs=jobs))
    assert_same_content(tmp_path / "j1.h5", tmp_path / "j2.h5")
    other = run_campaign(small_config("identify.seed=1"), jobs=1)
    assert not np.array_equal(other.summary.mean, read_campaign_h5(tmp_path / "j1.h5").summary.mean)


@pytest.mark.parametrize("system", ["vehicle", "damper"])
def test_interrupted_campaign_resumes_to_the_same_result(tmp_path, system):
    """Two runs finished, then an interruption; the resumed campaign (on two workers) writes the uninterrupted
    campaign's content, for the car and for the damper (one runner)."""
    cfg = small_config() if system == "vehicle" else load_config(damper_config(tmp_path))
    write_campaign_h5(tmp_path / "whole.h5", run_campaign(cfg, jobs=1))

    def interrupt_after_two(done, total):
        if done == 2:
            raise KeyboardInterrupt

    partial = tmp_path / "part.h5.partial"
    with pytest.raises(KeyboardInterrupt):
        run_campaign(cfg, jobs=1, checkpoint_dir=partial, on_run=interrupt_after_two)
    assert len(list(partial.glob("run-*.npz"))) == 2
    seen, notes = [], []
    resumed = run_campaign(cfg, jobs=2, checkpoint_dir=partial, on_run=lambda d, n: seen.append(d), log=notes.append)
    assert seen[0] == 2 and notes == [f"note: resumed 2 of 4 runs from {partial}"]  # from the two finished runs
    write_campaign_h5(tmp_path / "part.h5", resumed)
    assert_same_content(tmp_path / "whole.h5", tmp_path / "part.h5")


def test_checkpoint_of_another_config_is_refused(tmp_path):
    from vehid_cli.core.errors import InputError

    partial = tmp_path / "c.partial"
    run_campaign(small_config("identify.runs=1"), jobs=1, checkpoint_dir=partial)
    with pytest.raises(InputError, match="different config"):
        run_campaign(small_config("identify.runs=1", "noise.level=0.2"), jobs=1, checkpoint_dir=partial)


def test_file_round_trip_and_summary_statistics(tmp_path):
    campaign = run_campaign(small_config(), jobs=1)
    write_campaign_h5(tmp_path / "c.h5", campaign)
    back = read_campaign_h5(tmp_path / "c.h5")
    s = back.summary
    est = np.array([r.estimate for r in back.records])
    np.testing.assert_allclose(s.mean, est.mean(axis=0))
    re_mean = 100 * (est.mean(axis=0) - back.truth) / back.truth
    np.testing.assert_allclose(s.re_percent, re_mean)
    assert s.nre_percent == pytest.approx(np.linalg.norm(re_mean))
    per_run = np.linalg.norm(100 * (est - back.truth) / back.truth, axis=1)
    assert s.per_run_nre_rms == pytest.approx(np.sqrt(np.mean(per_run**2)))
    assert s.nre_over_crlb == pytest.approx(s.per_run_nre_rms / back.bound.nre_rms_percent)
    assert all(r.evaluations <= 40 for r in back.records)


def test_identify_cli_writes_h5_and_spec_json(tmp_path):
    sets = [x for s in SMALL for x in ("--set", s)]
    res = vehid(
        "identify", BASE_CONFIG, *sets, "--runs", 2, "--jobs", 1, "-o", tmp_path / "c.h5", "--json", tmp_path / "c.json"
    )
    assert res.returncode == 0, res.stderr
    doc = json.loads((tmp_path / "c.json").read_text())
    for key in ("parameters", "truth", "mean", "re_percent", "nre_percent", "per_run_nre_percent", "crlb",
                "evaluations_per_run", "runs", "wall_s"):  # fmt: skip
        assert key in doc
    assert doc["parameters"] == ["m", "Ix", "Iy", "a1", "b1"] and doc["runs"] == 2
    assert set(doc["crlb"]["re_sd_percent"]) == set(doc["parameters"]) and doc["crlb"]["nre_rms_percent"] > 0
    assert "NRE of mean" in res.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.h5", "c.json"]  # checkpoint removed


def test_identify_from_measured_data_with_known_truth(tmp_path):
    data = needs_shared(VEHICLE_DATA / "bump_run_linear.csv")
    cfg = load_config(
        BASE_CONFIG,
        [
            "identify.runs=2",
            "identify.algorithm.name=lsq",
            "identify.objective=wls",
            "sensors=acc",
            "identify.truth=config",
            "noise.level=0",
        ],
    )
    campaign = run_campaign(cfg, data, jobs=1)
    # measured data: one fit (identify.runs=2 would fit the same data twice)
    assert len(campaign.records) == 1
    # its interval comes from the bound (at the declared truth here); the independent simulator's truth lies within
    est, sd = campaign.records[0].estimate, campaign.bound.sd
    assert np.all(np.abs(est - campaign.truth) < 3 * sd), (est, campaign.truth, sd)
    # lsq from the box centre (the truth, for symmetric bounds) on the independent 5 %-noise run
    assert campaign.sigma_source.startswith("estimated")
    assert campaign.summary.per_run_nre_rms < 4 * campaign.bound.nre_rms_percent
    assert np.all(np.array([r.cost for r in campaign.records]) < 1.2)  # chi² per sample near 1


@pytest.mark.parametrize(
    "args, fragment",
    [
        (["--set", "identify.bounds=[1.1, 1.3]"], "excludes"),
        (["--set", "identify.unknowns=[m, mass]"], "'mass' is not a vehicle parameter"),
        (["--set", "identify.algorithm.population=1"], "identify.algorithm.population"),
        (["--runs", "0"], "identify.runs"),
        (["-o", "/nonexistent-dir/c.h5"], "does not exist"),
        (["--set", "identify.objective=f1", "--set", "sensors=acc"], "f1 compares displacements"),
        (["--data", "{tmp}/missing.csv"], "file not found"),
    ],
)
def test_identify_bad_input_exits_2(tmp_path, args, fragment):
    args = [a.format(tmp=tmp_path) for a in args]
    if "-o" not in args:
        args += ["-o", str(tmp_path / "c.h5")]
    res = vehid("identify", BASE_CONFIG, *args)
    assert res.returncode == 2, res.stderr
    assert fragment in res.stderr and "Traceback" not in res.stderr
    assert not (tmp_path / "c.h5").exists()


def damper_config(tmp_path, runs: int = 4, budget: int = 150):
    """A small synthetic damper campaign (Bingham on a sine bench, 2 % force noise)."""
    cfg = {
        "system": "damper",
        "damper": {"model": "bingham", "parameters": {"k1": 2000.0, "x0": -0.05, "c0": 1500.0, "fc": 200.0}},
        "bench": {"excitation": "sine", "amplitude": 0.025, "frequency": 0.8, "cycles": 2, "dt": 0.002},
        "noise": {"level": 0.02},
        "identify": {"unknowns": ["k1", "c0", "fc"], "bounds": [0.5, 2.0], "budget": budget, "runs": runs},
    }
    path = tmp_path / "damper.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


@pytest.mark.parametrize("system", ["vehicle", "damper"])
def test_sigkilled_cli_campaign_resumes_to_the_same_file(tmp_path, system):
    """Acceptance: kill -9 a running `vehid identify` (2 worker processes), run it again, get the uninterrupted
    campaign's content, for the car and for the damper (one pipeline). The killed campaign's pool workers exit by
    themselves (SIGTERM, SIGINT: test_reliability)."""
    import os
    import signal
    import time

    if system == "vehicle":
        config = BASE_CONFIG
        sets = [x for s in SMALL + ["identify.runs=12", "identify.algorithm.iterations=30"] for x in ("--set", s)]
    else:
        config, sets = damper_config(tmp_path, runs=12, budget=400), []
    whole = vehid("identify", config, *sets, "--jobs", 1, "-o", tmp_path / "whole.h5")
    assert whole.returncode == 0, whole.stderr
    target = tmp_path / "killed.h5"
    cmd = [sys.executable, "-m", "vehid_cli", "identify", str(config), *sets, "--jobs", "2", "-o", str(target)]
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    partial = tmp_path / "killed.h5.partial"
    deadline = time.time() + 60
    while time.time() < deadline and len(list(partial.glob("run-*.npz"))) < 3:
        time.sleep(0.01)
    workers = children(proc.pid)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    finished_before = len(list(partial.glob("run-*.npz")))
    assert 3 <= finished_before < 12 and not target.exists()
    deadline = time.time() + 10
    while time.time() < deadline and any(running(w) for w in workers):
        time.sleep(0.05)
    assert workers and not any(running(w) for w in workers), "pool workers outlived their killed campaign"
    resumed = vehid("identify", config, *sets, "--jobs", 1, "-o", target)
    assert resumed.returncode == 0, resumed.stderr
    assert f"resumed {finished_before} of 12 runs" in resumed.stderr
    assert_same_content(tmp_path / "whole.h5", target)
    assert not partial.exists()


def test_damper_campaign_is_parallel_and_written_in_the_cars_layout(tmp_path):
    """The damper through the one runner: --jobs 1 and 2 give the same file, read back as a damper campaign with
    its findings, every fit within the exact evaluation budget."""
    cfg = load_config(damper_config(tmp_path))
    campaigns = {jobs: run_campaign(cfg, jobs=jobs) for jobs in (1, 2)}
    for jobs, campaign in campaigns.items():
        write_campaign_h5(tmp_path / f"j{jobs}.h5", campaign)
    assert_same_content(tmp_path / "j1.h5", tmp_path / "j2.h5")
    back = read_campaign_h5(tmp_path / "j2.h5")
    assert back.system == "damper" and back.findings.model == "bingham"
    assert [r.cost for r in back.records] == [r.cost for r in campaigns[2].records]
    assert all(r.evaluations == 150 for r in back.records)  # the evaluation budget, honoured exactly


def test_damper_estimates_reach_the_cramer_rao_bound(tmp_path):
    """30 synthetic bench runs (2 % white force noise, the shipped config): the spread of the estimates matches the
    bound computed from the model's sensitivities (a different computation: no optimizer involved)."""
    cfg = load_config(ROOT / "configs" / "dampers" / "synthetic_bingham.yaml", ["identify.runs=30"])
    campaign = run_campaign(cfg, jobs=2)
    s, b = campaign.summary, campaign.bound
    assert np.all(np.isfinite(b.re_sd_percent)) and b.identifiable.all()
    assert 0.7 < s.nre_over_crlb < 1.4, (s.re_sd_percent, b.re_sd_percent)
    assert np.all(np.abs(s.re_percent) < 3 * b.re_sd_percent / np.sqrt(30))  # the mean is unbiased


def test_identify_refuses_a_file_of_another_config_unless_forced(tmp_path):
    out = tmp_path / "c.h5"
    sets = [x for s in SMALL + ["identify.runs=2"] for x in ("--set", s)]
    assert vehid("identify", BASE_CONFIG, *sets, "-o", out).returncode == 0
    before = out.read_bytes()
    other = vehid("identify", BASE_CONFIG, *sets, "--set", "noise.level=0.2", "-o", out)
    assert other.returncode == 2 and "noise.level: 0.1 in the file, 0.2 now" in other.stderr
    assert "--force" in other.stderr and out.read_bytes() == before
    forced = vehid("identify", BASE_CONFIG, *sets, "--set", "noise.level=0.2", "-o", out, "--force")
    assert forced.returncode == 0, forced.stderr
    assert read_campaign_h5(out).config.noise.level == 0.2


def test_truth_cost_and_chi2_folded_into_the_run_are_what_simulating_gives():
    """A run's truth cost comes from the clean channels its noise was drawn on, and its chi2 from the residuals the
    search kept at its estimate: the same numbers as simulating the truth and the estimate again (bit for bit where
    the kept residuals are the problem's own evaluation at the estimate; lsq's last linearisation differs from the
    simulation by round-off), without the two simulations."""
    from vehid_cli.systems import build_system

    for cfg in (small_config(), small_config("identify.algorithm.name=lsq", "identify.objective=wls")):
        system = build_system(cfg)
        truth = system.box.truth
        for index in range(2):
            record = system.identify_run(index)
            problem = system.problem(system.reference(index))
            assert record.truth_cost == float(problem.cost(truth[None, :])[0])
            _, residuals = problem.residuals(record.estimate[None, :])
            assert record.chi2 == pytest.approx(float(np.mean(residuals**2)), rel=1e-12, abs=0)


def test_converged_means_no_worse_than_the_truth_on_the_same_data():
    polished = run_campaign(small_config("identify.algorithm.name=lsq", "identify.objective=wls"), jobs=1)
    assert polished.summary.converged == 4
    assert all(r.cost <= r.truth_cost for r in polished.records)
    starved = run_campaign(small_config("identify.algorithm.iterations=1"), jobs=1)  # 8 random points
    assert starved.summary.converged == 0
    assert all(r.cost > r.truth_cost for r in starved.records)


def test_local_methods_do_not_start_at_the_truth():
    """With symmetric bounds the box centre is the configured value: a 1-evaluation lsq must not land on it."""
    c = run_campaign(small_config("identify.algorithm.name=lsq", "identify.budget=1", "identify.runs=3"), jobs=1)
    assert all(r.evaluations == 1 for r in c.records)
    assert np.all(c.summary.per_run_nre_percent > 1.0)
    nominal = run_campaign(small_config("identify.algorithm.name=lsq", "identify.budget=1", "identify.start=nominal"))
    np.testing.assert_allclose(nominal.records[0].estimate, nominal.truth)


def test_noise_free_data_has_a_zero_bound_and_no_ratio():
    c = run_campaign(small_config("noise.level=0", "identify.runs=2"), jobs=1)
    assert c.bound.nre_rms_percent == 0.0 and np.all(c.bound.re_sd_percent == 0.0)
    assert c.summary.nre_over_crlb is None


def test_summary_against_hand_computed_numbers():
    """Two runs, truth (10, 4): estimates (11, 4) and (10, 3) -> mean (10.5, 3.5), RE of mean (5, -12.5) %."""
    from vehid_cli.campaign.runner import RunRecord, summarise
    from vehid_cli.identify.crlb import CramerRao

    recs = [
        RunRecord(i, np.array(e), 0.0, 10, 0, 0.0, np.array([10]), np.array([0.0]))
        for i, e in enumerate([(11.0, 4.0), (10.0, 3.0)])
    ]
    bound = CramerRao(("a", "b"), np.array([10.0, 4.0]), np.eye(2), np.array([3.0, 4.0]), 5.0, np.ones(2, bool), 1.0)
    s = summarise(("a", "b"), np.array([10.0, 4.0]), recs, bound, 1.0)
    np.testing.assert_allclose(s.re_percent, [5.0, -12.5])
    assert s.nre_percent == pytest.approx(np.hypot(5.0, 12.5))
    np.testing.assert_allclose(s.per_run_nre_percent, [10.0, 25.0])  # (10 %, 0) and (0, -25 %)
    assert s.per_run_nre_rms == pytest.approx(np.sqrt((100 + 625) / 2))
    assert s.nre_over_crlb == pytest.approx(np.sqrt((100 + 625) / 2) / 5.0)
    np.testing.assert_allclose(s.sd, [np.sqrt(0.5), np.sqrt(0.5)])


def test_failed_campaign_leaves_no_checkpoint_to_block_the_corrected_rerun(tmp_path):
    from vehid_cli.campaign.runner import Checkpoint

    partial = tmp_path / "c.h5.partial"
    with pytest.raises(KeyboardInterrupt):
        run_campaign(small_config(), jobs=1, checkpoint_dir=partial, on_run=_interrupt_before_any_run)
    assert not partial.exists()
    partial.mkdir()  # an empty checkpoint left by an older version: nothing to protect, started afresh
    Checkpoint(partial, "other").open()
    assert not partial.exists()


def _interrupt_before_any_run(done, total):
    raise KeyboardInterrupt


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """A campaign written by run_campaign_to_file (its checkpoint removed), and its bytes."""
    target = tmp_path_factory.mktemp("written") / "c.h5"
    run_campaign_to_file(small_config("identify.runs=2"), target, jobs=1)
    return target, target.read_bytes()


@pytest.mark.parametrize("leftover", [(), ("run-00000.npz",), ("run-00001.npz", ".run-00000.npz.a1b2c3d4.tmp")])
def test_a_checkpoint_left_beside_its_finished_file_is_removed_not_refused(tmp_path, written, leftover):
    """A kill inside the checkpoint's clean-up, after the campaign file was written, leaves c.h5.partial/ without
    campaign.json: the finished, checksummed file of the same config wins, the rerun computes nothing."""
    target = tmp_path / "c.h5"
    target.write_bytes(written[1])
    campaign = read_campaign_h5(target)
    partial = tmp_path / "c.h5.partial"
    partial.mkdir()
    for name in leftover:
        if name.startswith("run-"):
            campaign.records[int(name[4:9])].save(partial / name)
        else:
            (partial / name).write_bytes(b"half a record")
    messages, progress = [], []
    again = run_campaign_to_file(
        small_config("identify.runs=2"), target, jobs=1, log=messages.append, on_run=lambda d, n: progress.append(d)
    )
    assert messages == [f"note: {target} is complete for this config; removed the stale checkpoint {partial}"]
    assert not partial.exists() and progress == []  # nothing recomputed
    assert target.read_bytes() == written[1]  # not even rewritten
    np.testing.assert_array_equal([r.estimate for r in again.records], [r.estimate for r in campaign.records])
    np.testing.assert_array_equal(again.summary.mean, campaign.summary.mean)


def test_a_checkpoint_beside_another_configs_file_is_still_refused(tmp_path, written):
    """Only a file of the same campaign settles a checkpoint without campaign.json; else the refusal stands."""
    from vehid_cli.core.errors import InputError

    target = tmp_path / "c.h5"
    target.write_bytes(written[1])
    partial = tmp_path / "c.h5.partial"
    partial.mkdir()
    read_campaign_h5(target).records[0].save(partial / "run-00000.npz")
    other = small_config("identify.runs=2", "noise.level=0.2")
    with pytest.raises(InputError, match=r"another config or data \(noise.level: 0.1 in the file, 0.2 now\)"):
        run_campaign_to_file(other, target, jobs=1)
    with pytest.raises(InputError, match="no readable campaign.json"):  # --force: the checkpoint is still not ours
        run_campaign_to_file(other, target, jobs=1, force=True)
    assert (partial / "run-00000.npz").exists() and target.read_bytes() == written[1]


def test_checkpoint_removal_deletes_its_stamp_last(tmp_path, monkeypatch):
    """So a kill midway leaves a stamped checkpoint (fewer runs), never runs without campaign.json."""
    from pathlib import Path

    from vehid_cli.campaign.runner import Checkpoint

    partial = tmp_path / "c.h5.partial"
    partial.mkdir()
    for name in ("campaign.json", "run-00000.npz", "run-00001.npz", "zz.npz"):
        (partial / name).write_text("x")
    order, unlink = [], Path.unlink
    monkeypatch.setattr(Path, "unlink", lambda self, *a, **k: (order.append(self.name), unlink(self, *a, **k)))
    Checkpoint(partial, "").remove()
    assert order[-1] == "campaign.json" and not partial.exists()
    assert sorted(order) == ["campaign.json", "run-00000.npz", "run-00001.npz", "zz.npz"]


def test_json_is_strict_when_a_parameter_is_unidentifiable(tmp_path):
    sets = [x for s in SMALL + ["road.bump.heights=[0.05,0.05,0.05,0.05]", "identify.runs=2"] for x in ("--set", s)]
    res = vehid("identify", BASE_CONFIG, *sets, "--jobs", 1, "-o", tmp_path / "c.h5", "--json", tmp_path / "c.json")
    assert res.returncode == 0, res.stderr
    text = (tmp_path / "c.json").read_text()
    doc = json.loads(text, parse_constant=lambda c: pytest.fail(f"non-standard JSON constant {c}"))
    assert doc["crlb"]["re_sd_percent"]["Ix"] is None and doc["crlb"]["unidentifiable"] == ["Ix"]
    assert "cannot identify Ix" in res.stdout


@pytest.mark.parametrize("run, inadequate", [("bump_run_A.csv", True), ("bump_run_linear.csv", False)])
def test_identify_says_when_the_model_is_wrong(run, inadequate):
    """bump_run_A holds an effect the linear car lacks: with the noise estimated from the data alone, the residual
    power at the fit is far above the noise; the linear control run fits to the noise floor."""
    data = needs_shared(VEHICLE_DATA / run)
    cfg = load_config(
        BASE_CONFIG,
        ["identify.runs=1", "identify.algorithm.name=hybrid", "identify.objective=wls", "noise.level=0"],
    )
    s = run_campaign(cfg, data, jobs=1).summary
    assert s.model_inadequate is inadequate
    if not inadequate:
        assert s.chi2_median == pytest.approx(1.0, abs=5 * np.sqrt(2 / s.residual_samples))


# ------------------------------------------------------------------------------ tampered checkpoints (issue 22)

TINY = ("simulation.duration=0.5", "simulation.dt=0.005", "identify.algorithm.population=4",
        "identify.algorithm.iterations=2", "identify.runs=2")  # fmt: skip


@pytest.fixture(scope="module")
def tiny_checkpoint(tmp_path_factory):
    """A whole campaign's file and its checkpoint (both runs)."""
    d = tmp_path_factory.mktemp("tiny")
    write_campaign_h5(d / "whole.h5", run_campaign(small_config(*TINY), jobs=1, checkpoint_dir=d / "c.h5.partial"))
    return d


def _fields(path):
    with np.load(path) as z:
        return {k: z[k] for k in z.files if k != "sha256"}


def _rewrite(path, fields):
    """A record written with its digest recomputed: only validation can tell it is wrong."""
    from vehid_cli.identify.records import _digest

    with open(path, "wb") as fh:
        np.savez(fh, sha256=np.array(_digest(fields)), **fields)


@pytest.mark.parametrize(
    "field, value",
    [("estimate", np.ones(4)), ("estimate", np.ones((1, 5))), ("estimate", np.full(5, np.nan)),
     ("cost", np.array(["text"])), ("evaluations", np.array(-3)), ("history_evals", np.arange(99))],
    ids=["wrong length", "2-D", "NaN", "cost text", "negative count", "history length"],
)  # fmt: skip
def test_a_record_with_a_valid_digest_but_wrong_fields_is_redone(tmp_path, tiny_checkpoint, field, value):
    partial = tmp_path / "c.h5.partial"
    shutil.copytree(tiny_checkpoint / "c.h5.partial", partial)
    fields = _fields(partial / "run-00001.npz")
    fields[field] = value
    _rewrite(partial / "run-00001.npz", fields)
    messages = []
    resumed = run_campaign(small_config(*TINY), jobs=1, checkpoint_dir=partial, log=messages.append)
    assert any("run-00001.npz: damaged checkpoint record" in m for m in messages), messages
    write_campaign_h5(tmp_path / "c.h5", resumed)
    assert_same_content(tiny_checkpoint / "whole.h5", tmp_path / "c.h5")


def _replace(path, how):
    path.unlink()
    if how == "directory":
        path.mkdir()
    elif how == "fifo":
        os.mkfifo(path)
    elif how == "loop":
        os.symlink(path.name, path)


@pytest.mark.parametrize(
    "entry, how, outcome",
    [("run-00001.npz", "fifo", "redone"), ("run-00001.npz", "loop", "redone"),
     ("run-00001.npz", "directory", "holds a directory"),
     ("campaign.json", "fifo", "no readable campaign.json"), ("campaign.json", "directory", "holds a directory"),
     (".", "loop", "is not a directory")],
)  # fmt: skip
def test_entries_replaced_in_a_checkpoint_never_hang_and_are_named(tmp_path, tiny_checkpoint, entry, how, outcome):
    from vehid_cli.core.errors import InputError

    partial = tmp_path / "c.h5.partial"
    shutil.copytree(tiny_checkpoint / "c.h5.partial", partial)
    if entry == ".":
        shutil.rmtree(partial)
        os.symlink(partial.name, partial)
    else:
        _replace(partial / entry, how)
    messages = []
    if outcome == "redone":
        run_campaign(small_config(*TINY), jobs=1, checkpoint_dir=partial, log=messages.append)
        assert any(f"{entry}: damaged checkpoint record" in m for m in messages), messages
        return
    with pytest.raises(InputError, match=outcome) as caught:
        run_campaign(small_config(*TINY), jobs=1, checkpoint_dir=partial)
    assert str(partial) in str(caught.value) and os.path.lexists(partial)  # named, and nothing removed


def test_a_first_checkpoint_write_that_fails_leaves_no_checkpoint(tmp_path, monkeypatch):
    import errno

    import vehid_cli.core.files as files
    from vehid_cli.core.errors import DiskFull

    def full(path, directory=False):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(files, "_fsync", full)
    partial = tmp_path / "c.h5.partial"
    with pytest.raises(DiskFull, match="campaign.json"):
        run_campaign(small_config(*TINY), jobs=1, checkpoint_dir=partial)
    assert list(tmp_path.iterdir()) == []


def test_a_count_of_runs_beyond_any_campaign_is_refused_before_anything_is_sized(tmp_path):
    from vehid_cli.campaign.runner import MAX_RUNS
    from vehid_cli.core.errors import InputError

    with pytest.raises(InputError, match="identify.runs"):
        run_campaign(small_config(*TINY, f"identify.runs={MAX_RUNS + 1}"), jobs=1, checkpoint_dir=tmp_path / "p")
    assert list(tmp_path.iterdir()) == []


def test_an_output_that_is_a_directory_is_refused_before_any_run(tmp_path):
    from vehid_cli.core.errors import InputError

    (tmp_path / "c.h5").mkdir()
    with pytest.raises(InputError, match="not a regular file"):
        run_campaign_to_file(small_config(*TINY), tmp_path / "c.h5", jobs=1, force=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["c.h5"]
