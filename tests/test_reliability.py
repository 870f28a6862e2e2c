"""Nothing lost, nothing silently wrong (issue 7): signals, damaged files, locks, concurrent sweeps, penalties."""

from __future__ import annotations

import errno
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
import warnings
from pathlib import Path

import h5py
import numpy as np
import pytest

import vehid_cli.core.files as files_module
from tests.conftest import BASE_CONFIG, ROOT, SMALL, assert_same_content, children, running, sets, small_config, vehid
from tests.conftest import invoke as invoke_cli
from vehid_cli.campaign.results import read_campaign_h5, write_campaign_h5
from vehid_cli.campaign.runner import run_campaign, run_campaign_to_file
from vehid_cli.core.errors import InputError
from vehid_cli.core.locking import Busy, exclusive, lock_path
from vehid_cli.core.store import check_integrity

LONG = SMALL + ["identify.runs=12", "identify.algorithm.iterations=200"]  # about 0.3 s a run: time to interrupt


def invoke(*args):
    """`vehid ARGS` in this process: exit code and all its text (stdout then stderr)."""
    code, out, err = invoke_cli(*args)
    return code, out + err


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    path = tmp_path_factory.mktemp("whole") / "whole.h5"
    res = vehid("identify", BASE_CONFIG, *sets(LONG), "--jobs", 1, "-o", path)
    assert res.returncode == 0, res.stderr
    return path


# ------------------------------------------------------------------------------------------ signals


def _as_from_a_terminal() -> None:
    """The child as a shell in a terminal starts it: SIGINT at its default (a background job of a non-interactive
    shell, e.g. `make test &` or nohup, inherits SIGINT ignored, and Python then never sees Ctrl-C), and at a lower
    priority, so that on a loaded machine the test sees the 3rd run before the 12th ends."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)
    os.nice(10)


@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs Linux /proc")
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=lambda s: s.name)
def test_signalled_campaign_stops_cleanly_and_resumes_to_the_same_file(tmp_path, uninterrupted, sig):
    """SIGTERM (kill, a job scheduler) and SIGINT (Ctrl-C, to the whole process group) stop a 2-process campaign at
    once, leave the finished runs and no temporary file, and end the process by that signal; the pool's workers
    go too. The rerun resumes and writes the uninterrupted campaign's file. (SIGKILL: tests/test_campaign.py.)"""
    target = tmp_path / "c.h5"
    partial = tmp_path / "c.h5.partial"
    cmd = [sys.executable, "-m", "vehid_cli", "identify", str(BASE_CONFIG), *sets(LONG), "--jobs", "2", "-o", target]
    proc = subprocess.Popen(
        list(map(str, cmd)), cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        start_new_session=True, preexec_fn=_as_from_a_terminal,
    )  # fmt: skip
    deadline = time.time() + 120
    while time.time() < deadline and len(list(partial.glob("run-*.npz"))) < 3:
        time.sleep(0.01)
    workers = children(proc.pid)
    if sig == signal.SIGINT:
        os.killpg(proc.pid, sig)  # what Ctrl-C in a terminal does
    else:
        os.kill(proc.pid, sig)
    _, stderr = proc.communicate(timeout=30)
    assert proc.returncode == -sig, stderr  # ended by the signal, as shells and job schedulers expect
    assert "Traceback" not in stderr
    assert f"interrupted by {sig.name}" in stderr and "run the same command again to resume" in stderr
    finished = len(list(partial.glob("run-*.npz")))
    assert 3 <= finished < 12 and not target.exists()
    assert not list(tmp_path.glob(".c.h5.*.tmp")) and not list(partial.glob(".*.tmp"))
    deadline = time.time() + 10
    while time.time() < deadline and any(running(w) for w in workers):
        time.sleep(0.05)
    assert not any(running(w) for w in workers), "pool workers outlived their campaign"
    resumed = vehid("identify", BASE_CONFIG, *sets(LONG), "--jobs", 2, "-o", target)
    assert resumed.returncode == 0, resumed.stderr
    assert_same_content(uninterrupted, target)
    assert not partial.exists() and not lock_path(target).exists()


# ------------------------------------------------------------------------------------------ damaged files


def test_damaged_checkpoint_records_are_redone_with_a_warning(tmp_path):
    cfg = small_config("identify.runs=5")
    write_campaign_h5(tmp_path / "whole.h5", run_campaign(cfg, jobs=1))

    def stop_after_four(done, total):
        if done == 4:
            raise KeyboardInterrupt

    partial = tmp_path / "c.h5.partial"
    with pytest.raises(KeyboardInterrupt):
        run_campaign(cfg, jobs=1, checkpoint_dir=partial, on_run=stop_after_four)
    record = partial / "run-00001.npz"
    record.write_bytes(record.read_bytes()[: record.stat().st_size // 2])  # truncated (a full disk, a crash)
    flipped = bytearray((partial / "run-00002.npz").read_bytes())
    flipped[len(flipped) // 3] ^= 0xFF  # one bit pattern changed: the zip CRC catches it
    (partial / "run-00002.npz").write_bytes(bytes(flipped))
    shutil.copy(partial / "run-00000.npz", partial / "run-00003.npz")  # a record under another run's name
    (partial / ".run-00004.npz.x1y2.tmp").write_bytes(b"half a write")  # left by a kill during a save
    messages = []
    resumed = run_campaign(cfg, jobs=1, checkpoint_dir=partial, log=messages.append)
    warnings = [m for m in messages if m.startswith("warning:")]
    damaged = sorted(m.split(":")[1].strip() for m in warnings)
    assert damaged == [str(partial / f"run-0000{i}.npz") for i in (1, 2, 3)], messages
    assert all("damaged checkpoint record" in m and "redone" in m for m in warnings)
    assert f"note: resumed 1 of 5 runs from {partial}" in messages  # only run 0 survived whole
    assert not list(partial.glob(".*.tmp"))
    write_campaign_h5(tmp_path / "c.h5", resumed)
    assert_same_content(tmp_path / "whole.h5", tmp_path / "c.h5")


@pytest.fixture(scope="module")
def one_campaign(tmp_path_factory):
    path = tmp_path_factory.mktemp("one") / "c.h5"
    write_campaign_h5(path, run_campaign(small_config("identify.runs=2"), jobs=1))
    return path


def flip_byte_in(path: Path, dataset: str) -> None:
    with h5py.File(path, "r") as h5:
        offset = h5[dataset].id.get_offset()
    with open(path, "r+b") as fh:
        fh.seek(offset + 5)
        byte = fh.read(1)
        fh.seek(offset + 5)
        fh.write(bytes([byte[0] ^ 0x10]))


@pytest.mark.parametrize("damage", ["truncated", "flipped", "emptied"])
def test_damaged_campaign_file_is_refused_naming_it(tmp_path, one_campaign, damage):
    bad = tmp_path / "sweep" / "bad.h5"
    bad.parent.mkdir()
    shutil.copy(one_campaign, tmp_path / "sweep" / "good.h5")
    if damage == "truncated":
        bad.write_bytes(one_campaign.read_bytes()[: one_campaign.stat().st_size * 2 // 3])
    elif damage == "flipped":
        shutil.copy(one_campaign, bad)
        flip_byte_in(bad, "runs/estimate")  # HDF5 would read it: only the checksum tells
    else:
        bad.write_bytes(b"")
    with pytest.raises(InputError, match="bad.h5"):
        read_campaign_h5(bad)
    for target in (bad, bad.parent):  # a damaged file in a directory is an error too, never silently left out
        code, text = invoke("report", target)
        assert code == 2 and "bad.h5" in text and "Traceback" not in text, text
        assert ("neither a vehid checksum nor an HDF5 signature" if damage == "emptied" else "checksum") in text


def test_sweep_reruns_a_damaged_campaign_file_with_a_warning(tmp_path):
    args = ["sweep", BASE_CONFIG, "--vary", "noise.level=0.1,0.2", *sets(SMALL), "--runs", 2, "--jobs", 1]
    args += ["-o", tmp_path]
    code, text = invoke(*args)
    assert code == 0, text
    victim = tmp_path / "level-0.2.h5"
    good = read_campaign_h5(victim).summary.mean
    flip_byte_in(victim, "runs/cost")
    code, text = invoke(*args)
    assert code == 0, text
    assert "level-0.2.h5: damaged results file" in text and "running the campaign again" in text
    assert "1 campaign(s) run, 1 up to date" in text
    np.testing.assert_array_equal(read_campaign_h5(victim).summary.mean, good)


def test_files_record_their_provenance(one_campaign):
    with h5py.File(one_campaign) as h5:
        attrs = dict(h5.attrs)
    recorded = (
        "config_yaml", "config_sha256", "seed", "seed_scheme", "vehid_version", "git_commit", "host", "created_utc",
        "numpy_version", "scipy_version", "numba_version", "data_sha256",
    )  # fmt: skip
    for key in recorded:
        assert key in attrs, key
    assert attrs["seed"] == 2015 and attrs["data_sha256"] == "" and len(attrs["config_sha256"]) == 64
    head = one_campaign.read_bytes()[:512]  # the HDF5 user block: the checksum of the rest of the file
    assert head.startswith(b"vehid sha256 ") and check_integrity(one_campaign) == head[13:77].decode()


# ------------------------------------------------------------------------------------------ a full disk

SIM = ["simulation.duration=1.5", "simulation.dt=0.002"]


def fill_the_disk(monkeypatch) -> list[str]:
    """Make every HDF5 image write (data.write_bytes) meet a full disk; returns the files it refused."""
    refused = []

    def full(fh, data):
        refused.append(fh.name)
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(files_module, "_write_bytes", full)
    return refused


def temporaries(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.glob(".*.tmp"))


def test_simulate_into_a_full_disk_exits_2_naming_the_file_and_leaves_nothing(tmp_path, monkeypatch):
    target = tmp_path / "x.h5"
    refused = fill_the_disk(monkeypatch)
    code, text = invoke("simulate", BASE_CONFIG, *sets(SIM), "-o", target)
    assert code == 2, text
    assert text.strip() == f"error: no space left on device writing {target}" and refused, text
    assert not target.exists() and temporaries(tmp_path) == []
    monkeypatch.undo()
    stale = tmp_path / ".x.h5.123.tmp"  # what a killed (or crashed) writer left
    stale.write_bytes(b"\x89HDF half a file")
    code, text = invoke("simulate", BASE_CONFIG, *sets(SIM), "-o", target)
    assert code == 0 and f"wrote {target}" in text, text
    assert temporaries(tmp_path) == [] and sorted(p.name for p in tmp_path.iterdir()) == ["x.h5"]
    with h5py.File(target) as h5:
        assert h5.attrs["kind"] == "vehid.simulation" and h5["noisy/acc"].shape == (750, 4)


def test_identify_that_cannot_write_its_file_keeps_every_run_and_the_rerun_finishes_from_them(
    tmp_path, monkeypatch, one_campaign
):
    """The campaign file meets a full disk after all runs were checkpointed: exit 2 with the message, no
    temporary, the checkpoint kept; the rerun takes every run from it and writes the clean run's campaign."""
    target = tmp_path / "c.h5"
    refused = fill_the_disk(monkeypatch)
    code, text = invoke("identify", BASE_CONFIG, *sets(SMALL), "--runs", 2, "--jobs", 1, "-o", target)
    assert code == 2, text
    assert f"error: no space left on device writing {target}" in text and "Traceback" not in text, text
    assert [Path(r).name.startswith(".c.h5.") for r in refused] == [True]
    partial = tmp_path / "c.h5.partial"
    assert sorted(p.name for p in partial.iterdir()) == ["campaign.json", "run-00000.npz", "run-00001.npz"]
    assert not target.exists() and temporaries(tmp_path) == [] and temporaries(partial) == []
    monkeypatch.undo()
    progress = []
    run_campaign_to_file(small_config("identify.runs=2"), target, jobs=1, on_run=lambda d, n: progress.append((d, n)))
    assert progress == [(2, 2)]  # nothing recomputed
    assert not partial.exists() and check_integrity(target) is not None
    assert_same_content(one_campaign, target)


@pytest.mark.skipif(shutil.which("unshare") is None, reason="needs util-linux unshare")
def test_simulate_on_a_really_full_file_system_exits_2_without_a_crash(tmp_path):
    """On a 40 kB tmpfs (a user namespace's mount: no root needed where the kernel allows it) HDF5 used to
    crash the process (exit 139) after h5py's 'Exception ignored' tracebacks."""
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    probe = subprocess.run(["unshare", "-rm", "mount", "-t", "tmpfs", "-o", "size=40k", "none", str(mnt)],
                           capture_output=True)  # fmt: skip
    if probe.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs in a user namespace: {probe.stderr.decode().strip()}")
    target = mnt / "x.h5"
    script = (f"mount -t tmpfs -o size=40k none {mnt} && {sys.executable} -m vehid_cli simulate {BASE_CONFIG} "
              f"{' '.join(sets(SIM))} -o {target}; echo status=$?; ls -A {mnt}")  # fmt: skip
    res = subprocess.run(["unshare", "-rm", "sh", "-c", script], capture_output=True, text=True, cwd=ROOT)
    assert "status=2\n" in res.stdout and res.stdout.endswith("status=2\n"), (res.stdout, res.stderr)
    assert res.stderr.strip() == f"error: no space left on device writing {target}", res.stderr


# ------------------------------------------------------------------------------------------ locks


def test_lock_is_exclusive_removed_after_use_and_survives_a_waiter(tmp_path):
    target = tmp_path / "c.h5"
    order = []
    with exclusive(target):
        assert lock_path(target).exists()
        with pytest.raises(Busy, match="another vehid process"):
            with exclusive(target):
                pass

        def waiter():
            with exclusive(target, wait=True):
                order.append("waiter")

        thread = threading.Thread(target=waiter)
        thread.start()
        time.sleep(0.2)
        order.append("holder")
    thread.join(10)
    assert order == ["holder", "waiter"]
    assert not lock_path(target).exists()


def test_identify_into_a_file_another_process_writes_exits_2(tmp_path):
    target = tmp_path / "c.h5"
    with exclusive(target):
        code, text = invoke("identify", BASE_CONFIG, *sets(SMALL), "--runs", 1, "--jobs", 1, "-o", target)
    assert code == 2 and "another vehid process is writing this file" in text and str(target) in text, text
    assert not target.exists()
    with pytest.raises(Busy):
        with exclusive(target):
            run_campaign_to_file(small_config("identify.runs=1"), target, jobs=1)


def test_concurrent_identical_sweeps_share_the_work_and_lose_nothing(tmp_path):
    """Two `vehid sweep` processes with the same plan in one directory: every campaign is run exactly once (the
    second process skips or waits for what the first holds), every file is whole, the index complete."""
    args = ["sweep", BASE_CONFIG, "--vary", "identify.algorithm.name=de,cpso", "--vary", "noise.level=0.1,0.2",
            *sets(SMALL), "--runs", 3, "--jobs", 1, "-o", tmp_path]  # fmt: skip
    procs = [
        subprocess.Popen(
            [sys.executable, "-m", "vehid_cli", *map(str, args)],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        for _ in range(2)
    ]
    outputs = [p.communicate(timeout=300) for p in procs]
    assert all(p.returncode == 0 for p in procs), outputs
    ran = sum(int(o.split("campaign(s) run")[0].rsplit(" ", 2)[-2]) for o, _ in outputs)
    assert ran == 4, outputs
    files = sorted(tmp_path.glob("*.h5"))
    assert len(files) == 4
    for f in files:
        read_campaign_h5(f)  # whole, checksum verified
    assert (tmp_path / "index.csv").read_text().count("\n") == 5
    assert not list(tmp_path.glob(".*"))  # no lock or temporary file left


def test_sweeps_with_different_plans_merge_their_index(tmp_path):
    base = ["sweep", BASE_CONFIG, *sets(SMALL), "--runs", 1, "--jobs", 1, "-o", tmp_path]
    assert invoke(*base, "--vary", "noise.level=0.1,0.2")[0] == 0
    assert invoke(*base, "--vary", "identify.algorithm.name=de,cpso")[0] == 0
    index = (tmp_path / "index.csv").read_text()
    assert all(name in index for name in ("level-0.1.h5", "level-0.2.h5", "name-de.h5", "name-cpso.h5"))


def test_a_file_rewritten_by_another_sweep_with_another_config_is_not_overwritten(tmp_path):
    """While this sweep runs its first campaign, another process writes the second campaign's file with another
    config: this sweep leaves that file alone and says so (exit 2), rather than lose its results."""
    from vehid_cli.campaign.sweep import parse_vary, plan_sweep, run_sweep

    planned = plan_sweep(BASE_CONFIG, SMALL + ["identify.runs=1"], parse_vary(["noise.level=0.1,0.2"]), tmp_path)
    intruder = run_campaign(small_config("identify.runs=1", "noise.level=0.2", "identify.seed=5"), jobs=1)

    def run_one(p):
        write_campaign_h5(p.path, run_campaign(p.config, jobs=1))
        if p.index == 0:
            write_campaign_h5(planned[1].path, intruder)  # "another sweep", meanwhile

    messages = []
    done = run_sweep(planned, (1, 1), run_one, log=messages.append)
    assert [p.index for p in done.ran] == [0] and [p.index for p in done.conflicts] == [1]
    assert read_campaign_h5(planned[1].path).config.identify.seed == 5
    assert "not overwritten" in messages[0]


# ------------------------------------------------------------------------------------------ numerical faults


def test_unstable_parameter_sets_are_penalised_counted_and_reported(tmp_path):
    """Negative damping in the box (put there past the config's physical ranges, which refuse it since issue 22):
    those cars blow up. The campaign completes without a floating-point warning, every cost is finite, and the
    penalised evaluations are counted in the campaign, its JSON and its file."""
    config = small_config("identify.unknowns=[m, cf, cr]", "identify.runs=2")
    limits = {"cf": (-60000.0, 60000.0), "cr": (-60000.0, 60000.0)}
    config = config.model_copy(update={"identify": config.identify.model_copy(update={"limits": limits})})
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        campaign = run_campaign(config, jobs=1)
    assert campaign.summary.penalised == sum(r.penalised for r in campaign.records) > 0
    assert all(np.isfinite(r.cost) for r in campaign.records)
    # run 1's 40 evaluations were all unstable: its "estimate" is meaningless, and the campaign says so
    assert [r.penalised for r in campaign.records][1] == 40 and campaign.summary.at_penalty == 1
    doc = campaign.to_json()
    assert doc["penalised_evaluations"] == campaign.summary.penalised and doc["runs_at_penalty"] == 1
    out = tmp_path / "c.h5"
    write_campaign_h5(out, campaign)
    with h5py.File(out) as h5:
        assert h5["summary"].attrs["penalised"] == campaign.summary.penalised
        assert list(h5["runs/penalised"][()]) == [r.penalised for r in campaign.records]
    # from the command line, such a box is refused before any run, naming the physical range it leaves
    extra = ["identify.unknowns=[m, cf, cr]", "identify.limits={cf: [-60000, 60000], cr: [-60000, 60000]}"]
    code, text = invoke("identify", BASE_CONFIG, *sets(SMALL + extra), "-o", tmp_path / "d.h5")
    assert code == 2 and "physical range" in text and not (tmp_path / "d.h5").exists(), text


@pytest.mark.parametrize("what", ["symlink", "directory", "fifo"])
def test_a_lock_file_replaced_by_something_else_is_refused_and_kept(tmp_path, what):
    """Never written through (a symlink to another file would have been truncated), never hanging on a FIFO."""
    target, lock = tmp_path / "c.h5", lock_path(tmp_path / "c.h5")
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me")
    if what == "symlink":
        lock.symlink_to(victim)
    elif what == "directory":
        lock.mkdir()
    else:
        os.mkfifo(lock)
    with pytest.raises(InputError, match=lock.name), exclusive(target):
        pass
    assert victim.read_text() == "keep me" and os.path.lexists(lock)


@pytest.mark.parametrize("code", [errno.ENOSPC, errno.EROFS], ids=["ENOSPC", "EROFS"])
def test_a_lock_whose_pid_cannot_be_written_is_removed_and_exits_2(tmp_path, monkeypatch, code):
    """A full disk (or a read-only folder) at the lock file's pid write: exit 2 naming the lock, no lock left."""
    import vehid_cli.core.locking as locking

    def refuse(fd, data):
        raise OSError(code, os.strerror(code))

    monkeypatch.setattr(locking.os, "write", refuse)
    target = tmp_path / "c.h5"
    code_, text = invoke("identify", BASE_CONFIG, *sets(SMALL), "--runs", 1, "--jobs", 1, "-o", target)
    monkeypatch.undo()
    assert code_ == 2 and lock_path(target).name in text and "Traceback" not in text, text
    assert list(tmp_path.iterdir()) == []


def test_holder_tells_a_held_lock_without_taking_or_making_it(tmp_path):
    from vehid_cli.core.locking import holder

    target = tmp_path / "c.h5"
    assert not holder(target) and not lock_path(target).exists()
    with exclusive(target):
        assert holder(target)
    assert not holder(target)
