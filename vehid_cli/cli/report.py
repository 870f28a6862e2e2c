"""`vehid report`: summary tables (and figures) of campaign files, in the format --format or -o's suffix names."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from ..core.errors import InputError
from .common import check_output_dir, check_writable, guarded, out, warn

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


def _tables(output: Path | None, tables: list) -> str | None:
    """Rich tables: printed to the terminal, or their plain text for --output."""
    if output is None:
        for table in tables:
            out.print(table)
        return None
    from ..report.campaigns import plain_text

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


@guarded
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
    html: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option(
            "--html", metavar="FILE", help="Write one self-contained page (tables, figures, provenance) to FILE.html."
        ),
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
    from ..report.campaigns import collect, load_published, render, report_notes, rich_tables, sweep_notes
    from ..report.compare import check_comparable

    tables = html is None or fmt is not None or output is not None  # --html alone writes the page only
    fmt = _report_format(fmt, output)
    if plots is not None:
        check_output_dir(plots, "--plots")
    if html is not None:
        check_writable(html, (".html", ".htm"))
    campaigns, files = collect(paths)
    notes = sweep_notes(paths)
    for note in notes:
        warn(f"warning: {note}")
    mixed = check_comparable(files, allow_mixed)
    for note in mixed:
        warn(f"note (--allow-mixed): {note}")
    if html is not None:
        from ..report.html import campaign_page, write_page

        write_page(html, campaign_page(campaigns, files, [*notes, *(f"--allow-mixed: {n}" for n in mixed)]))
        out.print(f"wrote {html}")
    if tables:
        if fmt == "table":
            text = _tables(output, [*rich_tables(campaigns, files), *report_notes(campaigns, files)])
        else:
            text = render(campaigns, files, fmt, load_published(published) if published else None)
        _emit(text, output)
    if plots is not None:
        from ..report.figures import write_plots

        written = write_plots(campaigns, files, plots)
        out.print(f"wrote {len(written)} figure(s) to {plots}")
