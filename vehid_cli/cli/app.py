"""The `vehid` command line assembled: the typer app, its --version callback, and the six commands registered in
the order help lists them. Each command lives in its own module (`simulate`, `identify`, `sweep`, `design`,
`report`, `diagnose`); what they share is in `common`. No command module imports this one.

Exit status (SPEC section 3): 0 success; 2 bad input, with one message naming the file, key or
column; 1 anything else. Set VEHID_DEBUG=1 to see the traceback of an unexpected error.
"""

from __future__ import annotations

import gc
import sys
from typing import Annotated

import typer

from .. import __version__
from .check import check
from .common import out
from .design import design
from .diagnose import diagnose
from .identify import identify
from .report import report
from .simulate import simulate
from .sweep import sweep

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


for _command in (simulate, check, identify, sweep, design, report, diagnose):
    app.command()(_command)


GC_YOUNG = 10_000  # allocations between two collections of the youngest generation (CPython's default: 700)


def run() -> None:
    """Console-script entry point. The cycle collector runs every GC_YOUNG allocations instead of 700: a command
    allocates millions of small objects over a heap of ~150 000 library objects, and the default thresholds collected
    it ~300 times with two full passes over that heap, ~0.1 s of a 3 s diagnosis's 2 (0.04 s so; cyclic garbage
    waits a little longer to be freed). On the way out every object still alive is frozen (`gc.freeze`): the
    interpreter's shutdown then does not collect and free them one by one, which took 0.3-0.4 s after every command
    (the modules of numba, llvmlite, SciPy and pydantic, torn down in cycles); the system reclaims the memory at once.
    Outputs are written and closed by then, and the standard streams are flushed as ever."""
    gc.set_threshold(GC_YOUNG, *gc.get_threshold()[1:])
    try:
        app()
    finally:
        gc.freeze()


if __name__ == "__main__":  # pragma: no cover
    run()
    sys.exit(0)
