"""`vehid sweep`: the Cartesian product of campaigns, one HDF5 file each plus index.csv, shardable for job arrays."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from ..core.errors import InputError
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
    import json

    from ..campaign.executor import check_executor_options, make_executor
    from ..campaign.runner import checkpoint_dir_for, run_campaign_to_file, saved_runs_note
    from ..campaign.sweep import check_no_other_campaigns, parse_shard, parse_vary, plan_sweep, run_sweep, write_index

    check_executor_options(executor, jobs=jobs, scheduler=scheduler)
    overrides = campaign_overrides(set_, runs, seed, jobs)
    k, n = parse_shard(shard)
    variations = parse_vary(vary)
    out_dir = output if output is not None else Path("runs") / f"sweep-{Path(config).stem}"
    check_output_dir(out_dir, "-o")
    planned = plan_sweep(config, overrides, variations, out_dir)
    if not force:
        check_no_other_campaigns(planned)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_index(out_dir, planned, log=warn)
    mine = [p for p in planned if p.index % n == k - 1]
    varied = json.dumps([v.key for v in variations])
    current: list[Path] = []

    def resume_hint() -> str:

        unfinished = [p for p in current[-1:] if checkpoint_dir_for(p).is_dir()]
        where = f"{saved_runs_note(unfinished[0]).split(';')[0]}; " if unfinished else ""
        return f"{where}finished campaigns are in {out_dir}; run the same sweep again to resume"

    with (
        interruptible(resume_hint, warn),
        make_executor(executor, jobs=jobs, scheduler=scheduler) as pool,
        progress_bar("sweep") as progress,
    ):
        bar = progress.add_task(f"shard {k}/{n}", total=len(mine))

        def run_one(p) -> None:
            progress.update(bar, description=p.path.stem)
            current.append(p.path)
            attrs = {"sweep_vary": varied, "sweep_overrides": " ".join(p.overrides)}
            s = run_campaign_to_file(
                p.config, p.path, executor=pool, log=warn, attrs=attrs, lock=False, force=True
            ).summary  # files of other configs were refused up front (unless --force)
            nre = "–" if s.nre_percent is None else f"{s.nre_percent:.3f} %"
            pen = f", {s.penalised} evaluations penalised" if s.penalised else ""
            pen += f" ({s.at_penalty} run(s) found no usable parameter set)" if s.at_penalty else ""
            out.print(f"{p.path.name}: NRE of mean {nre}{pen}, {s.wall_s:.1f} s")
            progress.advance(bar)

        def skipped(p) -> None:
            out.print(f"{p.path.name}: up to date, skipped")
            progress.advance(bar)

        done = run_sweep(planned, (k, n), run_one, skipped, log=warn)
    out.print(
        f"sweep {out_dir}: {len(done.ran)} campaign(s) run, {len(done.skipped)} up to date (shard {k}/{n})"
        + (f", {len(done.conflicts)} not overwritten" if done.conflicts else "")
    )
    if done.conflicts:
        raise InputError(
            f"{len(done.conflicts)} campaign file(s) were written meanwhile by another sweep with a different config "
            f"and were not overwritten ({', '.join(p.path.name for p in done.conflicts)}); give different sweeps "
            "different output directories",
            source=str(out_dir),
        )
