"""The executor options a command is given (`--executor`, `--jobs`, `--scheduler`), checked before any work.

Pure checks, with no import of the compiled kernels: a command refuses inconsistent options at once, before it reads
its logger files (`io.read.read_ahead`) and loads the library. `campaign.executor` builds the executor they choose.
"""

from __future__ import annotations

import re

from ..core.errors import InputError

EXECUTORS = ("local", "dask")
ADDRESS = re.compile(r"(?:(?:tcp|tls|ws|wss|ucx)://)?(?:\[[0-9A-Fa-f:.]+\]|[^\s/:\[\]]+):\d{1,5}")


def check_executor_options(kind: str = "local", *, jobs: int | None = None, scheduler: str | None = None) -> None:
    """InputError for an inconsistent choice of executor options (before any work is done)."""
    if kind not in EXECUTORS:
        raise InputError(f"--executor must be one of {', '.join(EXECUTORS)}, got '{kind}'")
    if kind == "local":
        if scheduler is not None:
            raise InputError("--scheduler is for --executor dask; the local executor needs no scheduler")
        if jobs is not None and jobs < 1:
            raise InputError(f"--jobs must be at least 1, got {jobs}")
        return
    if jobs is not None:
        raise InputError("--jobs sets local worker processes; with --executor dask the cluster's workers run the runs")
    if not scheduler:
        raise InputError("--executor dask needs --scheduler tcp://HOST:PORT (the address `dask scheduler` prints)")
    if not ADDRESS.fullmatch(scheduler):
        raise InputError(
            f"--scheduler expects an address tcp://HOST:PORT (as `dask scheduler` prints), got '{scheduler}'"
        )
