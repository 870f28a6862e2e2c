"""`vehid identify`: one statistical identification campaign (a car or a damper) into one HDF5 file."""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Optional

import typer

from ..core.interrupt import interruptible
from .common import (
    ExecutorOption,
    JobsOption,
    RunsOption,
    SaveConfigOption,
    SchedulerOption,
    SeedOption,
    SetOption,
    campaign_overrides,
    check_output_dir,
    check_writable,
    guarded,
    load_config,
    out,
    progress_bar,
    warn,
)


def default_output(config: Path, cfg, data: Sequence[Path] | None) -> Path:
    """The default results file: runs/<config>-<hash>.h5 for the config's own data, runs/<config>-<data>-<hash>.h5
    with --data (each data file's stem, joined by '+'; the hash then also covers the data files' absolute paths), so
    identifying the same config from another file never meets the earlier campaign's file."""
    if not data:
        return Path("runs") / f"{Path(config).stem}-{cfg.digest()[:8]}.h5"
    paths = "\n".join(str(Path(d).resolve()) for d in data)
    digest = hashlib.sha256(f"{cfg.digest()}\n{paths}".encode()).hexdigest()
    stems = "+".join(Path(d).stem for d in data)
    return Path("runs") / f"{Path(config).stem}-{stems}-{digest[:8]}.h5"


def _results_target(
    config: Path, cfg, data: Sequence[Path] | None, output: Path | None, json_out: Path | None, save: Path | None
) -> Path:
    """The results file (default: `default_output`), checked writable with the --json and --save-config files before
    any work."""
    if output is None:
        check_output_dir(Path("runs"), "the default output directory").mkdir(exist_ok=True)
        output = default_output(config, cfg, data)
    target = check_writable(output, (".h5", ".hdf5"))
    if json_out is not None:
        check_writable(json_out, (".json",))
    if save is not None:
        check_writable(save, (".yaml", ".yml"))
    return target


def _save_config(config: Path, overrides: list[str], campaign, results: Path, target: Path) -> None:
    """--save-config: the input config with the campaign's estimates in place."""
    from ..config.save import save_config
    from ..report.saved_config import campaign_found

    out.print(
        f"wrote {save_config(config, overrides, campaign_found(campaign, results), target, command='vehid identify')}"
    )


FORCE_HELP = (
    "Overwrite an output file that holds a campaign of another config; run with unknowns the data cannot separate."
)


@guarded
def identify(
    config: Annotated[Path, typer.Argument(metavar="CONFIG", help="Experiment config (YAML).", show_default=False)],
    data: Annotated[
        Optional[list[Path]],  # noqa: UP045
        typer.Option(
            "--data",
            metavar="FILE",
            help="Identify from this measured run instead of simulated data; repeat it to identify several runs "
            "jointly (one parameter set).",
        ),
    ] = None,
    runs: RunsOption = None,
    seed: SeedOption = None,
    jobs: JobsOption = None,
    output: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option(
            "-o",
            "--output",
            metavar="FILE",
            help="Campaign file (.h5); default runs/<config>-<hash>.h5 (with --data: runs/<config>-<data>-<hash>.h5).",
        ),
    ] = None,
    json_out: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option("--json", metavar="FILE", help="Also write the SPEC JSON summary here."),
    ] = None,
    set_: SetOption = None,
    save_config: SaveConfigOption = None,
    executor: ExecutorOption = "local",
    scheduler: SchedulerOption = None,
    force: Annotated[bool, typer.Option("--force", help=FORCE_HELP)] = False,
    no_checks: Annotated[
        bool,
        typer.Option(
            "--no-checks", help="Fit even when a channel fails a check that makes the fit meaningless (vehid check)."
        ),
    ] = False,
) -> None:
    """Run a statistical identification campaign (a car or a damper): one HDF5 file, and the summary table.

    Each run identifies from its own noise realisation with its own optimizer stream, so results are
    identical for any --jobs and executor (--executor dask --scheduler tcp://HOST:PORT runs them on a Dask
    cluster). Finished runs are kept in <output>.partial/ until the campaign completes: rerun the same
    command to resume an interrupted campaign (Ctrl-C, SIGTERM, a killed job).
    """

    from ..campaign.options import check_executor_options
    from ..core.provenance import ask_early
    from ..io.read import read_ahead

    check_executor_options(executor, jobs=jobs, scheduler=scheduler)
    cfg = load_config(config, campaign_overrides(set_, runs, seed, jobs))
    target = _results_target(config, cfg, data, output, json_out, save_config)
    ask_early()  # git's commit and the processor (h5py's import) asked before numba's LLVM library is mapped
    with read_ahead(data or cfg.data_runs()):  # the logger files read before the compiled kernels are imported
        from ..campaign.executor import make_executor
        from ..campaign.runner import run_campaign_to_file, saved_runs_note
        from ..core.jsonio import write_json
        from ..report.campaigns import campaign_notes, rich_tables
        from ..systems import system_class

        with (
            interruptible(lambda: saved_runs_note(target), warn),
            make_executor(executor, jobs=jobs, scheduler=scheduler) as pool,
            progress_bar("identify") as progress,
        ):
            objective = system_class(cfg).objective_label(cfg)
            bar = progress.add_task(f"{cfg.identify.algorithm.name}/{objective}", total=None)
            campaign = run_campaign_to_file(
                cfg, target, data or None, executor=pool, log=warn, force=force, checks=not no_checks,
                on_run=lambda d, n: progress.update(bar, completed=d, total=n),
            )  # fmt: skip
    if json_out is not None:
        write_json(json_out, campaign.to_json())
    for shown in (*rich_tables([campaign], [str(target)]), *campaign_notes(campaign)):  # the tables, then the notes
        out.print(shown)
    out.print(f"wrote {target}" + (f" and {json_out}" if json_out else ""))
    if save_config is not None:
        _save_config(config, campaign_overrides(set_, runs, seed, jobs), campaign, target, save_config)
