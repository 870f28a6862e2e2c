"""`vehid sweep`: the Cartesian product of campaigns, one HDF5 file each plus index.csv, shardable for job arrays."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Optional

import typer

from ..core.interrupt import interruptible
from .common import (
    ExecutorOption,
    JobsOption,
    RunsOption,
    SchedulerOption,
    SeedOption,
    SetOption,
    campaign_overrides,
    check_output_dir,
    guarded,
    out,
    progress_bar,
    warn,
)

if TYPE_CHECKING:  # the library is imported inside the command
    from ..campaign.sweep import SweepOutcome


def _campaign_line(path: Path, summary) -> str:
    """The line printed when a sweep's campaign finishes: its file, the NRE of the mean, penalties, wall time."""
    nre = "–" if summary.nre_percent is None else f"{summary.nre_percent:.3f} %"
    pen = f", {summary.penalised} evaluations penalised" if summary.penalised else ""
    pen += f" ({summary.at_penalty} run(s) found no usable parameter set)" if summary.at_penalty else ""
    return f"{path.name}: NRE of mean {nre}{pen}, {summary.wall_s:.1f} s"


def _sweep_line(out_dir: Path, done: SweepOutcome, shard: tuple[int, int]) -> str:
    """The closing line: how many campaigns this process ran, skipped and (conflicts) left alone."""
    k, n = shard
    line = f"sweep {out_dir}: {len(done.ran)} campaign(s) run, {len(done.skipped)} up to date (shard {k}/{n})"
    return line + (f", {len(done.conflicts)} not overwritten" if done.conflicts else "")


def _resume_hint(started: Sequence[Path], out_dir: Path) -> str:
    """What an interrupted sweep says: where the unfinished campaign's runs are kept, and how to resume."""
    from ..campaign.runner import checkpoint_dir_for, saved_runs_note

    unfinished = [p for p in started[-1:] if checkpoint_dir_for(p).is_dir()]
    where = f"{saved_runs_note(unfinished[0]).split(';')[0]}; " if unfinished else ""
    return f"{where}finished campaigns are in {out_dir}; run the same sweep again to resume"


def _planned(config: Path, vary: Sequence[str], output: Path | None, overrides: Sequence[str], force: bool):
    """(variations, output directory, campaigns) of a sweep, checked before any work: --vary parsed, the directory
    (-o, default runs/sweep-<config>) writable, no file in it of another config unless --force; index.csv written."""
    from ..campaign.sweep import check_no_other_campaigns, parse_vary, plan_sweep, write_index

    variations = parse_vary(vary)
    out_dir = output if output is not None else Path("runs") / f"sweep-{Path(config).stem}"
    check_output_dir(out_dir, "-o")
    planned = plan_sweep(config, overrides, variations, out_dir)
    if not force:
        check_no_other_campaigns(planned)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_index(out_dir, planned, log=warn)
    return variations, out_dir, planned


@guarded
def sweep(
    config: Annotated[
        Path, typer.Argument(metavar="CONFIG", help="Base experiment config (YAML).", show_default=False)
    ],
    vary: Annotated[
        list[str],
        typer.Option("--vary", metavar="KEY=V1,V2", help="dotted.key=v1,v2,... (repeatable): the product is swept."),
    ],
    output: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option(
            "-o", "--output", metavar="DIR", help="Directory of campaign files (default runs/sweep-<config>)."
        ),
    ] = None,
    shard: Annotated[
        Optional[str],  # noqa: UP045
        typer.Option("--shard", metavar="K/N", help="K/N: run only this share, for job arrays."),
    ] = None,
    runs: RunsOption = None,
    seed: SeedOption = None,
    jobs: JobsOption = None,
    set_: SetOption = None,
    executor: ExecutorOption = "local",
    scheduler: SchedulerOption = None,
    force: Annotated[
        bool, typer.Option("--force", help="Overwrite campaign files in the directory that hold other configs.")
    ] = False,
) -> None:
    """Run the Cartesian product of campaigns (a car or a damper), one HDF5 file each, plus index.csv.

    Campaigns whose file already holds the same resolved config are skipped, so a sweep can be rerun
    to finish what an interrupted one left; --shard K/N splits the work among independent processes, and
    any number of sweeps or shards may share the output directory (each campaign runs under a lock).
    --executor dask --scheduler tcp://HOST:PORT runs every campaign's runs on a Dask cluster.
    """
    from ..campaign.executor import make_executor
    from ..campaign.options import check_executor_options
    from ..campaign.runner import run_campaign_to_file
    from ..campaign.sweep import campaign_attrs, check_no_conflicts, parse_shard, run_sweep, shard_of

    check_executor_options(executor, jobs=jobs, scheduler=scheduler)
    overrides = campaign_overrides(set_, runs, seed, jobs)
    k, n = parse_shard(shard)
    variations, out_dir, planned = _planned(config, vary, output, overrides, force)
    started: list[Path] = []
    with (
        interruptible(lambda: _resume_hint(started, out_dir), warn),
        make_executor(executor, jobs=jobs, scheduler=scheduler) as pool,
        progress_bar("sweep") as progress,
    ):
        bar = progress.add_task(f"shard {k}/{n}", total=len(shard_of(planned, (k, n))))

        def run_one(p) -> None:
            progress.update(bar, description=p.path.stem)
            started.append(p.path)
            summary = run_campaign_to_file(
                p.config, p.path, executor=pool, log=warn, attrs=campaign_attrs(variations, p), lock=False, force=True
            ).summary  # files of other configs were refused up front (unless --force)
            out.print(_campaign_line(p.path, summary))
            progress.advance(bar)

        def skipped(p) -> None:
            out.print(f"{p.path.name}: up to date, skipped")
            progress.advance(bar)

        done = run_sweep(planned, (k, n), run_one, skipped, log=warn)
    out.print(_sweep_line(out_dir, done, (k, n)))
    check_no_conflicts(done, out_dir)
