"""Executors (issue 7): a campaign gives the same file on a local pool, in-process and on a Dask cluster; the
executor options fail cleanly (exit 2) when they cannot work."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from concurrent.futures import ProcessPoolExecutor

import pytest

from tests.conftest import BASE_CONFIG, ROOT, SMALL, assert_same_content, invoke, sets, small_config, vehid
from vehid_cli.campaign.executor import DaskExecutor, LocalExecutor, identity_mismatch, make_executor
from vehid_cli.campaign.results import write_campaign_h5
from vehid_cli.campaign.runner import run_campaign
from vehid_cli.config import load_config
from vehid_cli.core.errors import InputError

distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module")
def cluster():
    """A two-worker Dask cluster on the loopback interface (worker processes, one thread each)."""
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
    ) as c:
        yield c


def test_local_executor_yields_every_result_in_process_and_in_a_pool():
    for jobs in (1, 2):
        with LocalExecutor(jobs) as ex:
            assert sorted(ex.map_unordered(pow, 2, range(6))) == [1, 2, 4, 8, 16, 32]
            assert sorted(ex.map_unordered(pow, 3, range(3))) == [1, 3, 9]  # the pool is reused


def test_dask_campaigns_are_bit_identical_to_local_ones(cluster, tmp_path):
    """Three campaigns on one cluster (its workers compile once, then serve them all), two of the car and one of a
    damper (the same runner ships either system), against local execution."""
    damper = load_config(
        ROOT / "configs" / "dampers" / "synthetic_bingham.yaml", ["identify.runs=3", "identify.budget=80"]
    )
    configs = {
        "de": small_config(), "abc": small_config("identify.algorithm.name=abc", "identify.runs=5"), "damper": damper,
    }  # fmt: skip
    with DaskExecutor(cluster.scheduler_address) as ex:
        for name, cfg in configs.items():
            write_campaign_h5(tmp_path / f"{name}-dask.h5", run_campaign(cfg, executor=ex))
    for name, cfg in configs.items():
        write_campaign_h5(tmp_path / f"{name}-local.h5", run_campaign(cfg, jobs=1))
        assert_same_content(tmp_path / f"{name}-dask.h5", tmp_path / f"{name}-local.h5")


def test_identify_cli_on_dask_resumes_a_local_checkpoint(cluster, tmp_path):
    """Half the runs locally (interrupted), the rest on the cluster: the file of an uninterrupted local campaign."""
    cfg = small_config()
    write_campaign_h5(tmp_path / "whole.h5", run_campaign(cfg, jobs=1))

    def stop_after_two(done, total):
        if done == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_campaign(cfg, jobs=1, checkpoint_dir=tmp_path / "c.h5.partial", on_run=stop_after_two)
    res = vehid(
        "identify", BASE_CONFIG, *sets(SMALL), "-o", tmp_path / "c.h5", "--executor", "dask",
        "--scheduler", cluster.scheduler_address,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "Traceback" not in res.stderr
    assert_same_content(tmp_path / "whole.h5", tmp_path / "c.h5")
    assert not (tmp_path / "c.h5.partial").exists()


def test_a_worker_with_other_code_is_refused(cluster):
    with DaskExecutor(cluster.scheduler_address) as ex:
        ex.identity = dict(ex.identity, numpy="0.0.1")  # as if this process ran another NumPy than the workers
        with pytest.raises(InputError, match="other code than this process: numpy"):
            list(ex.map_unordered(pow, 2, range(3)))
    assert identity_mismatch({"vehid": "1", "git_commit": "abc"}, {"vehid": "1", "git_commit": "unknown"}) == []
    assert identity_mismatch({"vehid": "1"}, {"vehid": "2"}) == ["vehid 2 (here 1)"]


def test_unreachable_scheduler_exits_2_quickly(tmp_path):
    env = dict(os.environ, VEHID_DASK_TIMEOUT="1")
    res = vehid(
        "identify", BASE_CONFIG, "--runs", 1, "-o", tmp_path / "c.h5", "--executor", "dask",
        "--scheduler", "tcp://127.0.0.1:9", env=env, timeout=60,
    )  # fmt: skip
    assert res.returncode == 2, res.stderr
    assert "cannot reach a Dask scheduler" in res.stderr and "tcp://127.0.0.1:9" in res.stderr
    assert "Traceback" not in res.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    "args, fragment",
    [
        (["--executor", "dask"], "needs --scheduler"),
        (["--executor", "dask", "--scheduler", "tcp://127.0.0.1:9", "--jobs", "2"], "--jobs sets local"),
        (["--scheduler", "tcp://127.0.0.1:9"], "--scheduler is for --executor dask"),
        (["--executor", "slurm"], "--executor must be one of local, dask"),
        (["--executor", "dask", "--scheduler", "no-port"], "expects an address tcp://HOST:PORT"),
    ],
)
@pytest.mark.parametrize("command", ["identify", "sweep"])
def test_executor_options_bad_input_exit_2(tmp_path, command, args, fragment):
    extra = ["--vary", "noise.level=0.1,0.2"] if command == "sweep" else []
    code, out, err = invoke(command, BASE_CONFIG, *extra, "--runs", 1, "-o", tmp_path / "out.h5", *args)
    assert code == 2, out + err
    assert fragment in err and "Traceback" not in out + err
    assert not (tmp_path / "out.h5").exists()


def test_make_executor_without_distributed_says_what_to_install(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import fails as if it were not installed
    with pytest.raises(InputError, match=r"pip install 'dask\[distributed\]'"):
        make_executor("dask", scheduler="tcp://127.0.0.1:9")


def test_a_pool_worker_whose_parent_is_already_gone_exits():
    """The race of a parent killed between a worker's fork and its setup: the worker is told its parent's pid, so
    it does not take its new parent (init) for it and wait forever."""
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    code = f"from vehid_cli.campaign.executor import _exit_with_parent; _exit_with_parent({int(gone.stdout)})"
    res = subprocess.run([sys.executable, "-c", code], timeout=30, cwd=ROOT)
    assert res.returncode == 1


@pytest.mark.slow
def test_a_dask_worker_killed_mid_campaign_changes_nothing(tmp_path):
    """SIGKILL one of two workers after 4 of 12 runs: its runs are rescheduled (the nanny restarts it) and the
    campaign ends with the file of a local campaign."""
    import signal

    cfg = small_config("identify.runs=12", "identify.algorithm.iterations=30")
    write_campaign_h5(tmp_path / "local.h5", run_campaign(cfg, jobs=1))
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None
    ) as cluster:
        with distributed.Client(cluster.scheduler_address) as client:
            victim = min(client.run(os.getpid).values())
        killed = []

        def kill_after_four(done, total):
            if done == 4 and not killed:
                os.kill(victim, signal.SIGKILL)
                killed.append(victim)

        with DaskExecutor(cluster.scheduler_address) as ex:
            write_campaign_h5(tmp_path / "dask.h5", run_campaign(cfg, executor=ex, on_run=kill_after_four))
    assert killed
    assert_same_content(tmp_path / "local.h5", tmp_path / "dask.h5")


def _slow(shared, item):
    time.sleep(shared)
    return item


def test_aborting_a_pool_with_cancelled_runs_prints_no_traceback(monkeypatch):
    """Ctrl-C or SIGTERM mid-campaign: the unfinished runs are cancelled, the workers terminated. CPython 3.11's
    pool thread then raised InvalidStateError for each cancelled run (a traceback on stderr, a flaky CI failure)."""
    raised = []
    monkeypatch.setattr(threading, "excepthook", lambda args: raised.append(args.exc_type))
    shutdown = ProcessPoolExecutor.shutdown

    def late_shutdown(self, *args, **kwargs):  # the pool's thread sees the dead workers first, as under load
        time.sleep(0.5)
        return shutdown(self, *args, **kwargs)

    monkeypatch.setattr(ProcessPoolExecutor, "shutdown", late_shutdown)
    ex = LocalExecutor(2)
    results = ex.map_unordered(_slow, 0.3, range(40))
    next(results)  # one run finished; the rest are queued or running
    results.close()  # the consumer stops: queued runs are cancelled
    ex.close(abort=True)
    assert raised == []
