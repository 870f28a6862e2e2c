"""`vehid check`: every measured channel against the configured model, before any fit: a table per channel (sign,
scale, swap, delay, clipping, held samples, drift, offset, noise), the findings that would stop `identify` and their
fixes, and the SPEC section 6 JSON."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from .common import SetOption, check_writable, guarded, load_config, out

SYMBOL = {"ok": "ok", "warning": "WARN", "fail": "FAIL"}
HEADER = {"dropout": "held", "offset": "offs", "trigger": "trig"}  # short headers: the table fits 80 columns


def _table(system, checks):
    """One row per channel, one column per check: its status."""
    from rich.table import Table

    names = list(dict.fromkeys(f.check for f in checks.findings))
    table = Table(title=f"checks of {system.data_file} against the configured model", title_justify="left")
    table.add_column("channel", no_wrap=True)
    for name in names:
        table.add_column(HEADER.get(name, name), justify="center", no_wrap=True, min_width=4)
    for channel in dict.fromkeys(f.channel for f in checks.findings):
        status = {f.check: f.status for f in checks.findings if f.channel == channel}
        table.add_row(channel, *(SYMBOL.get(status.get(n, ""), "–") for n in names))
    return table


@guarded
def check(
    config: Annotated[Path, typer.Argument(metavar="CONFIG", help="Experiment config (YAML).", show_default=False)],
    data: Annotated[
        Optional[list[Path]],  # noqa: UP045
        typer.Option("--data", metavar="FILE", help="The measured run to check (repeatable; else data.files)."),
    ] = None,
    json_out: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option("--json", metavar="FILE", help="Write the checks as JSON (SPEC section 6)."),
    ] = None,
    set_: SetOption = None,
) -> None:
    """Check every measured channel against the configured model before any fit.

    The configured car predicts each channel's sign, scale, timing and range on the run's own road: a sensor upside
    down, a channel in another unit than declared, two connectors swapped, a delayed clock, a saturating sensor,
    held samples, a drifting bias, an unexpected offset and noise far from the assumed one are named with their
    evidence and fix. The last line says whether identify would stop (a finding that makes any fit meaningless).
    """
    from ..core.jsonio import write_json
    from ..io.read import read_ahead

    if json_out is not None:
        check_writable(json_out, (".json",))
    runs = data or load_config(config, set_ or ()).data_runs()
    with read_ahead(runs):  # logger files read before the compiled kernels' imports
        from ..systems import check_config

        system, checks = check_config(config, set_ or (), data or None)
    out.print(_table(system, checks))
    for f in checks.problems:
        fix = f"; fix: {f.fix}" if f.fix else ""
        out.print(f"{f.status} {f.check} {f.channel}: {f.message}{fix}", markup=False, highlight=False)
    if json_out is not None:
        write_json(json_out, {"checks": checks.to_json()})
        out.print(f"wrote {json_out}")
    if checks.stopping:
        out.print(f"identify would stop: {len(checks.stopping)} failure(s) make any fit meaningless", markup=False)
    else:
        out.print(f"{len(checks.problems)} warning(s), no failure" if checks.problems else "every check passed")
