"""What the `vehid` commands share: the consoles, the shared options, the error guard, progress, output checks and
config loading. Imports only typer, rich and `vehid_cli.core` at module level: the library is imported when a
command runs, so `vehid --help` starts in a fraction of a second.

Exit status (SPEC section 3): 0 success; 2 bad input, with one message naming the file, key or
column, or an output that cannot be written (a full disk, a read-only folder: nothing partial left); 1 anything
else. Set VEHID_DEBUG=1 to see the traceback of an unexpected error.
"""

from __future__ import annotations

import functools
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Optional

import typer
from rich.console import Console

from ..core.errors import InputError, WriteFailed

if TYPE_CHECKING:  # the library is imported inside the commands: `vehid --help` starts in a fraction of a second
    from ..config import Config, DamperConfig

out = Console(soft_wrap=True)
err = Console(stderr=True, highlight=False, soft_wrap=True)


SetOption = Annotated[
    Optional[list[str]],  # noqa: UP045 - typer needs Optional here
    typer.Option(
        "--set", metavar="KEY=VALUE", help="Override a config value: dotted.key=value (repeatable).", show_default=False
    ),
]
SaveConfigOption = Annotated[
    Optional[Path],  # noqa: UP045 - typer needs Optional here
    typer.Option(
        "--save-config",
        metavar="FILE.yaml",
        help="Write the input config with the identified values in place (each with its 95 % interval and the run "
        "it came from): vehid simulate / identify FILE.yaml continue from it.",
    ),
]
RunsOption = Annotated[
    Optional[int],  # noqa: UP045 - typer needs Optional here
    typer.Option("--runs", metavar="N", help="Runs per campaign (identify.runs)."),
]
SeedOption = Annotated[
    Optional[int],  # noqa: UP045
    typer.Option("--seed", metavar="N", help="Campaign seed (identify.seed)."),
]
JobsOption = Annotated[
    Optional[int],  # noqa: UP045
    typer.Option("--jobs", metavar="N", help="Worker processes (default: all cores)."),
]
ExecutorOption = Annotated[
    str,
    typer.Option(
        "--executor",
        metavar="local|dask",
        help="Where the runs execute: local (this machine; --jobs processes) or dask (a cluster).",
    ),
]
SchedulerOption = Annotated[
    Optional[str],  # noqa: UP045 - typer needs Optional here
    typer.Option(
        "--scheduler", metavar="ADDRESS", help="Dask scheduler address, tcp://HOST:PORT (with --executor dask)."
    ),
]


def warn(message: str) -> None:
    """A message on stderr, as given (no rich markup)."""
    err.print(message, markup=False)


def load_config(path: Path, overrides: Sequence[str] = ()) -> Config | DamperConfig:
    """config.load_config, imported when a command runs (not when the CLI starts)."""
    from ..config import load_config as load

    return load(path, overrides)


def check_writable(path: Path, suffixes: Sequence[str]) -> Path:
    """data.check_writable, imported when a command runs."""
    from ..core.files import check_writable as check

    return check(path, suffixes)


def check_output_dir(path: Path, option: str) -> Path:
    """data.check_writable_dir for an option's directory: created if needed and probed, before any work."""
    from ..core.files import check_writable_dir

    return check_writable_dir(path, option)


def guarded(command):
    """Turn InputError into exit 2 with its message, anything unexpected into exit 1, never a traceback."""

    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        try:
            return command(*args, **kwargs)
        except InputError as exc:
            err.print(f"error: {exc}", markup=False)
            raise typer.Exit(2) from None
        except WriteFailed as exc:  # a full disk or quota, a read-only folder: the write was undone, exit 2
            err.print(f"error: {exc}", markup=False)
            raise typer.Exit(2) from None
        except (typer.Exit, typer.Abort, KeyboardInterrupt):
            raise
        except Exception as exc:  # noqa: BLE001 - the last line of defence of the CLI
            if os.environ.get("VEHID_DEBUG"):
                raise
            err.print(
                f"internal error: {exc.__class__.__name__}: {exc} (set VEHID_DEBUG=1 for the traceback)", markup=False
            )
            raise typer.Exit(1) from None

    return wrapper


def campaign_overrides(set_: list[str] | None, runs: int | None, seed: int | None, jobs: int | None) -> list[str]:
    """--set lines plus the --runs/--seed shortcuts (kept in the resolved config, for provenance)."""
    from ..config import Override

    overrides = list(set_ or ())
    if runs is not None:
        overrides.append(Override(f"identify.runs={runs}", "--runs"))
    if seed is not None:
        overrides.append(Override(f"identify.seed={seed}", "--seed"))
    check_jobs(jobs)
    return overrides


JOBS_MAX = 1024  # worker processes: more than any machine's cores, fewer than a fork bomb


def check_jobs(jobs: int | None) -> None:
    """--jobs in 1..JOBS_MAX, before any work."""
    if jobs is not None and not 1 <= jobs <= JOBS_MAX:
        raise InputError(f"--jobs must be in [1, {JOBS_MAX}] (worker processes), got {jobs}")


def progress_bar(verb: str):
    """A rich progress bar on stderr on a terminal; elsewhere (logs, CI) one plain stderr line per finished step."""
    if not err.is_terminal:
        from ..core.progress import PlainProgress

        return PlainProgress(verb, {"sweep": "campaign", "design": "step", "diagnose": "step"}.get(verb, "run"), warn)
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )  # fmt: skip

    return Progress(
        TextColumn(f"[bold]{verb}[/] {{task.description}}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
        TextColumn("ETA"), TimeRemainingColumn(), console=err, transient=True,
    )  # fmt: skip


def stage_hook(bar, units: dict[str, str] | None = None):
    """A library loop's progress hook (stage, done, total) shown on `bar`: a task per stage, made at its first call;
    `units` names what a stage's steps are (by the stage's last word: 'candidates' -> 'candidate')."""
    tasks: dict[str, int] = {}

    def progress(stage: str, done: int, total: int | None) -> None:
        if stage not in tasks:
            unit = (units or {}).get(stage.rsplit(" ", 1)[-1])
            tasks[stage] = bar.add_task(stage, total=total, **({"unit": unit} if unit else {}))
        bar.update(tasks[stage], completed=done, total=total)

    return progress
