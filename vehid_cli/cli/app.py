"""The `vehid` command line: each command parses its options and calls the library, nothing more.

Exit status (SPEC section 3): 0 success; 2 bad input, with one message naming the file, key or
column; 1 anything else. Set VEHID_DEBUG=1 to see the traceback of an unexpected error.
"""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Optional

import typer
from rich.console import Console

from .. import __version__
from ..core.errors import DiskFull, InputError
from ..core.interrupt import interruptible

if TYPE_CHECKING:  # the library is imported inside the commands: `vehid --help` starts in a fraction of a second
    from ..config import Config, DamperConfig

app = typer.Typer(
    add_completion=False,
    context_settings={"help_option_names": ["-h", "--help"]},
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
    help="vehid: vehicle and suspension parameter identification.",
)


def _argument_type_hidden(display_type_rich):
    """Help shows an argument by its metavar alone (CONFIG, PATH...), without typer's <path> or <list[Path]>."""

    def display(self, ctx):
        return None if self.metavar else display_type_rich(self, ctx)

    return display


if hasattr(typer.core.TyperArgument, "display_type_rich"):  # typer >= 0.16; the help test guards the output
    typer.core.TyperArgument.display_type_rich = _argument_type_hidden(typer.core.TyperArgument.display_type_rich)
out = Console(soft_wrap=True)
err = Console(stderr=True, highlight=False, soft_wrap=True)


SetOption = Annotated[
    Optional[list[str]],  # noqa: UP045 - typer needs Optional here
    typer.Option(
        "--set", metavar="KEY=VALUE", help="Override a config value: dotted.key=value (repeatable).", show_default=False
    ),
]


def load_config(path: Path, overrides: Sequence[str] = ()) -> Config | DamperConfig:
    """config.load_config, imported when a command runs (not when the CLI starts)."""
    from ..config import load_config as load

    return load(path, overrides)


def check_writable(path: Path, suffixes: Sequence[str]) -> Path:
    """data.check_writable, imported when a command runs."""
    from ..core.files import check_writable as check

    return check(path, suffixes)


def _guarded(command):
    """Turn InputError into exit 2 with its message, anything unexpected into exit 1, never a traceback."""

    @functools.wraps(command)
    def wrapper(*args, **kwargs):
        try:
            return command(*args, **kwargs)
        except InputError as exc:
            err.print(f"error: {exc}", markup=False)
            raise typer.Exit(2) from None
        except DiskFull as exc:  # a full disk or quota: the write was undone (nothing partial left), exit 1
            err.print(f"error: {exc}", markup=False)
            raise typer.Exit(1) from None
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


def _campaign_overrides(set_: list[str] | None, runs: int | None, seed: int | None, jobs: int | None) -> list[str]:
    """--set lines plus the --runs/--seed shortcuts (kept in the resolved config, for provenance)."""
    from ..config import Override

    overrides = list(set_ or ())
    if runs is not None:
        overrides.append(Override(f"identify.runs={runs}", "--runs"))
    if seed is not None:
        overrides.append(Override(f"identify.seed={seed}", "--seed"))
    if jobs is not None and jobs < 1:
        raise InputError(f"--jobs must be at least 1, got {jobs}")
    return overrides


def _progress(verb: str):
    """A rich progress bar on stderr on a terminal; elsewhere (logs, CI) one plain stderr line per finished step."""
    if not err.is_terminal:
        from ..core.progress import PlainProgress

        return PlainProgress(verb, {"sweep": "campaign", "design": "step"}.get(verb, "run"), _warn)
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

    return Progress(
        TextColumn(f"[bold]{verb}[/] {{task.description}}"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(),
        console=err, transient=True,
    )  # fmt: skip


def _results_target(config: Path, cfg, output: Path | None, json_out: Path | None) -> Path:
    """The results file (default runs/<config>-<hash>.h5), checked writable with the --json file before any work."""
    if output is None:
        check_output_dir(Path("runs"), "the default output directory").mkdir(exist_ok=True)
        output = Path("runs") / f"{Path(config).stem}-{cfg.digest()[:8]}.h5"
    target = check_writable(output, (".h5", ".hdf5"))
    if json_out is not None:
        check_writable(json_out, (".json",))
    return target


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


def _warn(message: str) -> None:
    err.print(message, markup=False)


def _version(value: bool) -> None:
    if value:
        out.print(f"vehid {__version__}")
        raise typer.Exit()


@app.callback()
def main(
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version and exit.")
    ] = False,
) -> None:
    """vehid: vehicle and suspension parameter identification."""


@app.command()
@_guarded
def simulate(
    config: Annotated[Path, typer.Argument(metavar="CONFIG", help="Experiment config (YAML).", show_default=False)],
    output: Annotated[
        Path,
        typer.Option(
            "-o",
            "--output",
            metavar="FILE",
            help="Output file: .csv (measurement format), .h5, or .mf4 (a car's run as a data logger records it).",
            show_default=False,
        ),
    ],
    road: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option("--road", metavar="FILE", help="Take road1..road4 and the time grid from this measurement file."),
    ] = None,
    plot: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option("--plot", metavar="FILE", help="Also draw the responses to this PNG."),
    ] = None,
    seed: Annotated[
        Optional[int],  # noqa: UP045
        typer.Option("--seed", metavar="N", help="Seed of the noise (default identify.seed)."),
    ] = None,
    set_: SetOption = None,
) -> None:
    """Simulate the configured car on its road and write a vehicle measurement file.

    CSV holds the noisy channels of the configured sensors (Eq. 15 or noise.sigma; --set noise.level=0 for clean
    ones); HDF5 holds clean and noisy; MDF4 the noisy channels and the road as a logger records them. The noise
    is the noise stream of run 0 of the campaign with the same seed.
    """
    from ..systems import simulation_suffixes, write_simulation

    target = check_writable(output, simulation_suffixes())
    if plot is not None:
        check_writable(plot, (".png",))
    if seed is not None and seed < 0:
        raise InputError(f"--seed must be a non-negative integer, got {seed}")
    cfg = load_config(config, set_ or ())
    seed = cfg.identify.seed if seed is None else seed
    simulated = write_simulation(cfg, target, seed, road, origin=f"simulate {config}")
    if plot is not None:
        from ..report.figures import plot_simulation

        plot_simulation(cfg, simulated, plot)
    out.print(f"wrote {target}: {simulated.summary}" + (f"; figure {plot}" if plot else ""))


@app.command()
@_guarded
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
        typer.Option("-o", "--output", metavar="FILE", help="Campaign file (.h5); default runs/<config>-<hash>.h5."),
    ] = None,
    json_out: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option("--json", metavar="FILE", help="Also write the SPEC JSON summary here."),
    ] = None,
    set_: SetOption = None,
    executor: ExecutorOption = "local",
    scheduler: SchedulerOption = None,
    force: Annotated[
        bool, typer.Option("--force", help="Overwrite an output file that holds a campaign of another config.")
    ] = False,
) -> None:
    """Run a statistical identification campaign (a car or a damper): one HDF5 file, and the summary table.

    Each run identifies from its own noise realisation with its own optimizer stream, so results are
    identical for any --jobs and executor (--executor dask --scheduler tcp://HOST:PORT runs them on a Dask
    cluster). Finished runs are kept in <output>.partial/ until the campaign completes: rerun the same
    command to resume an interrupted campaign (Ctrl-C, SIGTERM, a killed job).
    """

    from ..campaign.executor import check_executor_options, make_executor
    from ..campaign.runner import run_campaign_to_file, saved_runs_note
    from ..core.jsonio import write_json
    from ..report import campaign_notes, rich_tables
    from ..systems import system_class

    check_executor_options(executor, jobs=jobs, scheduler=scheduler)
    cfg = load_config(config, _campaign_overrides(set_, runs, seed, jobs))
    target = _results_target(config, cfg, output, json_out)
    with (
        interruptible(lambda: saved_runs_note(target), _warn),
        make_executor(executor, jobs=jobs, scheduler=scheduler) as pool,
        _progress("identify") as progress,
    ):
        objective = system_class(cfg).objective_label(cfg)
        bar = progress.add_task(f"{cfg.identify.algorithm.name}/{objective}", total=None)
        campaign = run_campaign_to_file(
            cfg, target, data or None, executor=pool, log=_warn, force=force,
            on_run=lambda d, n: progress.update(bar, completed=d, total=n),
        )  # fmt: skip
    if json_out is not None:
        write_json(json_out, campaign.to_json())
    for table in rich_tables([campaign], [str(target)]):
        out.print(table)
    for note in campaign_notes(campaign):
        out.print(note)
    out.print(f"wrote {target}" + (f" and {json_out}" if json_out else ""))


@app.command()
@_guarded
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
    overrides = _campaign_overrides(set_, runs, seed, jobs)
    k, n = parse_shard(shard)
    variations = parse_vary(vary)
    out_dir = output if output is not None else Path("runs") / f"sweep-{Path(config).stem}"
    check_output_dir(out_dir, "-o")
    planned = plan_sweep(config, overrides, variations, out_dir)
    if not force:
        check_no_other_campaigns(planned)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_index(out_dir, planned, log=_warn)
    mine = [p for p in planned if p.index % n == k - 1]
    varied = json.dumps([v.key for v in variations])
    current: list[Path] = []

    def resume_hint() -> str:

        unfinished = [p for p in current[-1:] if checkpoint_dir_for(p).is_dir()]
        where = f"{saved_runs_note(unfinished[0]).split(';')[0]}; " if unfinished else ""
        return f"{where}finished campaigns are in {out_dir}; run the same sweep again to resume"

    with (
        interruptible(resume_hint, _warn),
        make_executor(executor, jobs=jobs, scheduler=scheduler) as pool,
        _progress("sweep") as progress,
    ):
        bar = progress.add_task(f"shard {k}/{n}", total=len(mine))

        def run_one(p) -> None:
            progress.update(bar, description=p.path.stem)
            current.append(p.path)
            attrs = {"sweep_vary": varied, "sweep_overrides": " ".join(p.overrides)}
            s = run_campaign_to_file(
                p.config, p.path, executor=pool, log=_warn, attrs=attrs, lock=False, force=True
            ).summary  # files of other configs were refused up front (unless --force)
            nre = "–" if s.nre_percent is None else f"{s.nre_percent:.3f} %"
            pen = f", {s.penalised} evaluations penalised" if s.penalised else ""
            pen += f" ({s.at_penalty} run(s) found no usable parameter set)" if s.at_penalty else ""
            out.print(f"{p.path.name}: NRE of mean {nre}{pen}, {s.wall_s:.1f} s")
            progress.advance(bar)

        def skipped(p) -> None:
            out.print(f"{p.path.name}: up to date, skipped")
            progress.advance(bar)

        done = run_sweep(planned, (k, n), run_one, skipped, log=_warn)
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


@app.command()
@_guarded
def design(
    config: Annotated[
        Path, typer.Argument(metavar="CONFIG", help="Car config with a design: section (YAML).", show_default=False)
    ],
    output: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option("-o", "--output", metavar="FILE", help="Write the designed test as a ready config (.yaml)."),
    ] = None,
    json_out: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option("--json", metavar="FILE", help="Write the comparison as JSON (docs/design.md)."),
    ] = None,
    plots: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option("--plots", metavar="DIR", help="Figures: the bound against speed and the left/right ratio."),
    ] = None,
    verify: Annotated[
        int,
        typer.Option(
            "--verify", metavar="N", help="Run an N-run campaign on the configured and the designed test (0: none)."
        ),
    ] = 0,
    jobs: JobsOption = None,
    set_: SetOption = None,
) -> None:
    """Plan the test that identifies the car best, within the limits of the config's design: section.

    Speed, bump heights (left/right and, with design.heights.per_axle, front/rear), shape, length, duration and
    optionally N sensors among candidates are chosen to minimise the Cramér–Rao bound of the configured
    identification (design.criterion: nre, d_optimal, worst, worst:<param>). Prints the configured and the
    designed test side by side, names the unknowns the configured test cannot identify with the cheapest change
    that fixes it; --verify N checks the prediction with campaigns of N runs.
    """
    from ..campaign.executor import LocalExecutor
    from ..core.jsonio import write_json
    from ..design.search import design_test
    from ..report.design import design_json, notes, rich_tables, write_config, write_plots
    from ..systems import system_class

    for path, suffixes in ((output, (".yaml", ".yml")), (json_out, (".json",))):
        if path is not None:
            check_writable(path, suffixes)
    if plots is not None:
        check_output_dir(plots, "--plots")
    if verify < 0:
        raise InputError(f"--verify must be a non-negative number of runs, got {verify}")
    if jobs is not None and jobs < 1:
        raise InputError(f"--jobs must be at least 1, got {jobs}")
    cfg = load_config(config, set_ or ())
    if not system_class(cfg).designable:
        raise InputError("vehid design plans a car's test (system: vehicle)", source=str(config), key="system")
    with interruptible(lambda: "nothing was written", _warn), LocalExecutor(jobs) as pool, _progress("design") as bar:
        tasks: dict[str, int] = {}

        def progress(stage: str, done: int, total: int | None) -> None:
            if stage not in tasks:
                tasks[stage] = bar.add_task(stage, total=total)
            bar.update(tasks[stage], completed=done, total=total)

        result = design_test(cfg, executor=pool, verify=verify, progress=progress)
    for table in rich_tables(result):
        out.print(table)
    for note in notes(result):
        out.print(note, markup=False)
    if output is not None:
        write_config(result, output)
        out.print(f"wrote {output}")
    if json_out is not None:
        write_json(json_out, design_json(result, None if output is None else str(output)))
        out.print(f"wrote {json_out}")
    if plots is not None:
        for path in write_plots(result, plots):
            out.print(f"wrote {path}")


REPORT_FORMATS = ("table", "md", "csv", "latex", "json")  # report.FORMATS (tested equal), not imported at start-up
REPORT_SUFFIXES = {".md": "md", ".csv": "csv", ".tex": "latex", ".latex": "latex", ".json": "json", ".txt": "table"}


def _report_format(fmt: str | None, output: Path | None) -> str:
    """--format, else the one -o's suffix implies, else table; -o is checked writable. Exit 2 if they disagree."""
    if fmt is not None and fmt not in REPORT_FORMATS:
        raise InputError(f"--format must be one of {', '.join(REPORT_FORMATS)}, got '{fmt}'")
    if output is None:
        return fmt or "table"
    suffix = output.suffix.lower()
    implied = REPORT_SUFFIXES.get(suffix)
    known = ", ".join(f"{k} ({v})" for k, v in REPORT_SUFFIXES.items())
    if implied is None:
        raise InputError(
            f"-o: cannot tell the report format from the suffix '{suffix}'; use one of {known}", source=str(output)
        )
    if fmt is not None and fmt != implied:
        raise InputError(
            f"--format {fmt} disagrees with -o {output} (a '{suffix}' file is written as {implied}); "
            f"give one of them, or a matching pair: {known}"
        )
    check_writable(output, tuple(REPORT_SUFFIXES))
    return implied


def check_output_dir(path: Path, option: str) -> Path:
    """data.check_writable_dir for an option's directory: created if needed and probed, before any work."""
    from ..core.files import check_writable_dir

    return check_writable_dir(path, option)


@app.command()
@_guarded
def report(
    paths: Annotated[
        list[Path],
        typer.Argument(metavar="PATH", help="Campaign files (.h5) or directories of them.", show_default=False),
    ],
    fmt: Annotated[
        Optional[str],  # noqa: UP045
        typer.Option(
            "--format",
            metavar="|".join(REPORT_FORMATS),
            help="Default: from -o's suffix (.md, .csv, .tex/.latex, .json, .txt), else table.",
            show_default=False,
        ),
    ] = None,
    output: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option("-o", "--output", metavar="FILE", help="Write the report to this file instead of the terminal."),
    ] = None,
    plots: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option("--plots", metavar="DIR", help="Write PNG figures into this directory."),
    ] = None,
    published: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option("--published", metavar="FILE", help="YAML of published values to set beside ours (md, latex)."),
    ] = None,
    allow_mixed: Annotated[
        bool,
        typer.Option(
            "--allow-mixed", help="Report campaigns of different experiments, data or code versions together."
        ),
    ] = False,
) -> None:
    """Summary tables (and figures) of campaign files: algorithms side by side, with the Cramér–Rao bound.

    A directory contributes every campaign file in it, so the shards of a sweep make one report. Campaigns
    of different experiments (config keys other than the method keys and a sweep's varied keys), data files
    or code versions are refused unless --allow-mixed is given.
    """
    from ..report import collect, load_published, render, rich_tables, sweep_notes
    from ..report.compare import check_comparable

    fmt = _report_format(fmt, output)
    if plots is not None:
        check_output_dir(plots, "--plots")
    campaigns, files = collect(paths)
    for note in sweep_notes(paths):
        _warn(f"warning: {note}")
    for note in check_comparable(files, allow_mixed):
        _warn(f"note (--allow-mixed): {note}")
    if fmt == "table":
        text = _tables(output, rich_tables(campaigns, files))
    else:
        text = render(campaigns, files, fmt, load_published(published) if published else None)
    _emit(text, output)
    if plots is not None:
        from ..report.figures import write_plots

        written = write_plots(campaigns, files, plots)
        out.print(f"wrote {len(written)} figure(s) to {plots}")


def _tables(output: Path | None, tables: list) -> str | None:
    """Rich tables: printed to the terminal, or their plain text for --output."""
    if output is None:
        for table in tables:
            out.print(table)
        return None
    from ..report import plain_text

    return plain_text(tables)


def _emit(text: str | None, output: Path | None) -> None:
    """A report's text: to the terminal, or written atomically to --output."""
    if text is None:
        return
    if output is None:
        out.print(text, markup=False, highlight=False)
        return
    from ..core.files import atomic_path

    with atomic_path(output) as tmp:
        tmp.write_text(text)
    out.print(f"wrote {output}")


@app.command()
@_guarded
def diagnose(
    config: Annotated[
        Path, typer.Argument(metavar="CONFIG", help="Experiment config (YAML): the declared model.", show_default=False)
    ],
    data: Annotated[
        Optional[list[Path]],  # noqa: UP045
        typer.Option(
            "--data",
            metavar="FILE",
            help="Measurement file to fit and diagnose (a damper config may name it in data.file); repeat it to "
            "diagnose several runs of the car jointly (one parameter set).",
        ),
    ] = None,
    validate: Annotated[
        Optional[list[Path]],  # noqa: UP045
        typer.Option(
            "--validate", metavar="FILE", help="A run to judge the augmented model on (repeatable; else held-out data)."
        ),
    ] = None,
    json_out: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option("--json", metavar="FILE", help="Write the SPEC section 5 JSON here."),
    ] = None,
    plots: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option(
            "--plots", metavar="DIR", help="Write figures here: residual before/after, fingerprint, spectrum."
        ),
    ] = None,
    set_: SetOption = None,
) -> None:
    """Close the loop: fit, analyse the residual, rank candidates (missing effects, mis-set known parameters),
    add the best, re-fit; say whether the residual is now at the noise.

    Full car: J is wls (chi2 per sample); the noise is estimated from the data unless --set noise.level=Np
    (or the config's noise.sigma) gives it; the integrator is rk4 unless the config sets newmark; any sensor
    layout and logger file the config describes; --data repeated fits several runs jointly. Damper on a
    bench: J is Eq. 7; the validation runs are --validate, else the config's data.validate. A candidate is
    accepted when its likelihood-ratio test is significant (p below 1e-3 / number of candidates), it lowers
    the validation J, and the data tell it from the runner-up; a known parameter that explains as much wins
    over an effect.
    The verdict starts with adequate, found, incomplete or inconclusive (data too short, noisy or unexcited).
    """

    from ..core.jsonio import write_json
    from ..report.diagnosis import diagnosis_tables, plot_diagnosis_files
    from ..systems import diagnose_config

    if json_out is not None:
        check_writable(json_out, (".json",))
    if plots is not None:
        check_output_dir(plots, "--plots")
    say = lambda msg: err.print(msg, markup=False)  # noqa: E731
    result = diagnose_config(config, set_ or (), data or None, validate or (), log=say)
    doc = result.to_json()
    out.print(diagnosis_tables(result))
    for step in result.steps:
        out.print(
            f"added {step.effect}: J {step.J_before:.4g} -> {step.J_after:.4g}, "
            f"validation J {step.validation_J_before:.4g} -> {step.validation_J_after:.4g}"
        )
    for note in result.notes:
        out.print(f"note: {note}", markup=False)
    out.print(f"verdict: {result.verdict} ({result.wall_s:.1f} s)")
    if plots is not None:
        for path in plot_diagnosis_files(result, plots, (data[0] if data else config).stem):
            out.print(f"wrote {path}")
    if json_out is not None:
        write_json(json_out, doc)
        out.print(f"wrote {json_out}")


def run() -> None:
    """Console-script entry point."""
    app()


if __name__ == "__main__":  # pragma: no cover
    run()
    sys.exit(0)
