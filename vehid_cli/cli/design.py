"""`vehid design`: plan the test that identifies the car (or a rig) best, within the config's design: limits."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from ..core.errors import InputError
from ..core.interrupt import interruptible
from .common import (
    JobsOption,
    SetOption,
    check_jobs,
    check_output_dir,
    check_writable,
    guarded,
    load_config,
    out,
    progress_bar,
    stage_hook,
    warn,
)

VERIFY_MAX = 100_000  # runs of a verification campaign, as identify.runs


def _check_options(output: Path | None, json_out: Path | None, plots: Path | None, verify: int, jobs: int | None):
    """-o, --json and --plots checked writable, --verify and --jobs checked in range, before any work."""
    for path, suffixes in ((output, (".yaml", ".yml")), (json_out, (".json",))):
        if path is not None:
            check_writable(path, suffixes)
    if plots is not None:
        check_output_dir(plots, "--plots")
    if not 0 <= verify <= VERIFY_MAX:
        raise InputError(f"--verify must be a number of runs in [0, {VERIFY_MAX}], got {verify}")
    check_jobs(jobs)


def _print_design(result, output: Path | None, json_out: Path | None, plots: Path | None) -> None:
    """The comparison tables and notes on the terminal; the designed config, its JSON and figures where asked."""
    from ..core.jsonio import write_json
    from ..report.design import design_json, notes, rich_tables, write_config, write_plots

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


def _design_variables(cfg, output: Path | None, json_out: Path | None, plots: Path | None, verify: int,
                      jobs: int | None) -> None:  # fmt: skip
    """A test designed through the system's design variables (the rigs): the table, -o and --json."""
    from ..campaign.executor import LocalExecutor
    from ..core.jsonio import write_json
    from ..design.variables import design_variables_test
    from ..report.variable_design import design_json, notes, rich_table, write_config

    for given, option in ((plots is not None, "--plots"), (verify > 0, "--verify")):
        if given:
            raise InputError(f"{option} is not available for a {cfg.system} design yet", source=cfg.source)
    with interruptible(lambda: "nothing was written", warn), LocalExecutor(jobs) as pool:
        result = design_variables_test(cfg, pool)
    out.print(rich_table(result))
    for note in notes(result):
        out.print(note, markup=False)
    if output is not None:
        write_config(result, cfg.source, output)
        out.print(f"wrote {output}")
    if json_out is not None:
        write_json(json_out, design_json(result, None if output is None else str(output)))
        out.print(f"wrote {json_out}")


@guarded
def design(
    config: Annotated[
        Path,
        typer.Argument(metavar="CONFIG", help="Car or rig config with a design: section (YAML).", show_default=False),
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
    that fixes it; --verify N checks the prediction with campaigns of N runs. On a quarter or half car: the road
    chirp's band and amplitude, the force chirp's amplitude, the bump's speed and height (README).
    """
    from ..campaign.executor import LocalExecutor
    from ..design.search import design_test
    from ..systems import system_class

    _check_options(output, json_out, plots, verify, jobs)
    cfg = load_config(config, set_ or ())
    cls = system_class(cfg)
    if not cls.designable:
        raise InputError(f"vehid design has no test to plan for a {cls.name} yet", source=str(config), key="system")
    if cls.design_variables(cfg) is not None:
        _design_variables(cfg, output, json_out, plots, verify, jobs)
        return
    with interruptible(lambda: "nothing was written", warn), LocalExecutor(jobs) as pool, progress_bar("design") as bar:
        progress = stage_hook(bar, {"search": "generation"})
        result = design_test(cfg, executor=pool, verify=verify, progress=progress)
    _print_design(result, output, json_out, plots)
