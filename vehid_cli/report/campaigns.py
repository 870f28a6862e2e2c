"""Reports of campaign files: tables in several formats, their notes and provenance, and the system a campaign ran."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import yaml
from rich.console import Console
from rich.markup import escape

from ..campaign.results import CAMPAIGN_KIND, read_campaign_h5
from ..campaign.sweep import read_index
from ..core.errors import InputError, quote
from ..core.jsonio import to_json
from ..core.locking import holder
from ..core.store import open_results, read_results
from ..identify.records import Campaign
from ..systems import SYSTEMS, System

FORMATS = ("table", "md", "csv", "latex", "json")


def is_campaign_file(path: Path) -> bool:
    """A vehid campaign file? False for other HDF5 files; InputError for a file HDF5 cannot open (truncated or
    damaged): a report never drops a campaign silently."""
    try:
        _, tree = read_results(path, "campaign file")
    except FileNotFoundError:
        raise InputError("not found (removed while the report was made?)", source=str(path)) from None
    kind = tree.attrs.get("kind")
    return isinstance(kind, str) and kind == CAMPAIGN_KIND


def collect(paths: list[Path]) -> tuple[list[Campaign], list[str]]:
    """Read campaign files; a directory contributes the campaign files in it (other .h5 files are skipped),
    so the shards of a sweep written into one directory, or several directories, make one report."""
    files: list[Path] = []
    for path in paths:
        if path.is_dir():
            found = [f for f in sorted(path.glob("*.h5")) if is_campaign_file(f)]
            if not found:
                raise InputError("directory holds no campaign files (*.h5)", source=str(path))
            files.extend(found)
        else:
            files.append(path)
    if not files:
        raise InputError("no campaign files given")
    return [read_campaign_h5(f) for f in files], [str(f) for f in files]


def sweep_notes(paths: list[Path]) -> list[str]:
    """Warnings about unfinished sweeps in the directories among `paths`: campaigns index.csv lists that have
    no file yet (a shard not run, still running or failed), and checkpoints of campaigns: running now (a live
    process holds the campaign file's lock) or interrupted."""
    notes = []
    for path in paths:
        if not path.is_dir():
            continue
        index = path / "index.csv"
        if index.is_file():
            missing = [r["file"] for r in read_index(index) if not (path / r["file"]).exists()]
            if missing:
                shown = ", ".join(missing[:5]) + (", ..." if len(missing) > 5 else "")
                notes.append(
                    f"{index} lists {len(missing)} campaign(s) with no file yet ({shown}): a shard not run, still "
                    "running or failed; the report shows the finished ones"
                )
        for partial in sorted(path.glob("*.partial")):
            runs = len(list(partial.glob("run-*.npz"))) if partial.is_dir() else 0
            if holder(partial.with_name(partial.name.removesuffix(".partial"))):
                notes.append(f"{partial}: a campaign running now ({runs} finished run(s) so far); report again when "
                             "it is done")  # fmt: skip
            else:
                notes.append(
                    f"{partial}: an interrupted campaign ({runs} finished run(s)); rerun its command to finish it"
                )
    return notes


def load_published(path: Path) -> dict:
    """Published reference values (e.g. configs/gokdag2015/paper_tables.yaml) to set beside ours."""
    try:
        doc = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise InputError(f"cannot read published values ({exc.__class__.__name__})", source=str(path)) from None
    if not isinstance(doc, dict) or not isinstance(doc.get("tables"), list):
        raise InputError("expected a mapping with a 'tables' list", source=str(path), key="tables")
    return doc


def file_provenance(path: str) -> dict:
    """The provenance attributes a campaign file records (config hash, seed, code versions, host, time)."""
    keys = (
        "config_sha256", "seed", "data_file", "data_sha256", "vehid_version", "git_commit", "host", "python",
        "created_utc", "numpy_version", "scipy_version", "numba_version", "h5py_version", "pydantic_version",
        "sweep_vary",
    )  # fmt: skip
    h5 = open_results(path, CAMPAIGN_KIND, "campaign file")
    out = {"file_sha256": read_results(path, "campaign file")[0]}
    for k in keys:
        v = h5.attrs.get(k)
        if isinstance(v, np.ndarray) and v.size == 1:
            v = v.reshape(())[()]
        if isinstance(v, (str, bool, int, float, np.number, np.bool_)):
            out[k] = v.item() if hasattr(v, "item") else v
        elif v is not None:
            raise InputError(f"campaign file is damaged or was edited: attribute '{k}' should be a single value, "
                             f"found {quote(v, 80)}", source=str(path))  # fmt: skip
    return out


def system_of(campaigns: list[Campaign], files: list[str]) -> type[System]:
    """The one system the campaigns share (their tables differ by system); InputError naming a file otherwise."""
    first = campaigns[0].system
    for c, f in zip(campaigns, files, strict=True):
        if c.system != first:
            raise InputError(
                f"is a {c.system} campaign but {files[0]} is a {first} campaign; report each system separately",
                source=f,
            )
    if first not in SYSTEMS:
        raise InputError(f"a campaign of an unknown system '{first}'", source=files[0])
    return SYSTEMS[first]


def rich_tables(campaigns: list[Campaign], files: list[str]) -> list:
    """The terminal tables of the campaigns' system (the car's summary tables, a damper's parameters and J), each
    with its names and numbers whole (`whole_cells`) however narrow the terminal or CI log."""
    return [whole_cells(t) for t in system_of(campaigns, files).tables(campaigns, files)]


def whole_cells(table, width: int | None = None):
    """A rich table whose names (the first column: `tau_comp_rise`, `hysteresis.alpha_f`) are never cut to an
    ellipsis, and whose numbers are whole too when the console (`width`, default the terminal's; 80 in a pipe or CI
    log) has room for them, else folded onto a second line rather than cut; headers wrap at their words."""
    from rich.console import Console
    from rich.text import Text

    if not getattr(table, "columns", None):
        return table

    def longest(cells) -> int:
        return max((Text.from_markup(c).cell_len if isinstance(c, str) else c.cell_len for c in cells), default=0)

    def word(header) -> int:
        return max((len(w) for w in str(header).split()), default=0)

    first, rest = table.columns[0], table.columns[1:]
    first.min_width, first.no_wrap = max(longest(first._cells), word(first.header), 1), True
    need = [max(longest(c._cells), word(c.header), 1) for c in rest]
    room = (width or Console().width) - first.min_width - 3 * len(table.columns) - 1
    for column, n in zip(rest, need, strict=True):
        if sum(need) <= room:
            column.min_width = n
        else:
            column.overflow = "fold"
    return table


def campaign_notes(c: Campaign) -> list[str]:
    """What a user must know about a finished campaign beyond its table (rich markup): the findings of the checks
    and the intervals' notes made during the run, an estimate on its bound, a residual far from the noise with its
    worst channels, unidentifiable parameters, evaluations that got the penalty."""
    s = c.summary
    notes = [f"[yellow]warning:[/] {escape(w)}" for w in (*c.warnings, *c.advice())]
    total = int(s.evaluations.sum())
    if s.penalised:
        note = (
            f"{s.penalised} of {total} evaluations ({100 * s.penalised / max(total, 1):.2g} %) made the model unstable "
            "or non-finite and got the finite penalty cost (counted in 'penalised'; the runs went on)"
        )
        if s.at_penalty:
            note += (
                f"; [bold]{s.at_penalty} of {len(s.evaluations)} run(s) found no usable parameter set[/] (best cost = "
                "the penalty): their estimates are meaningless and bias the mean; narrow identify.bounds or "
                "identify.limits"
            )
        notes.append(f"[yellow]note:[/] {note}")
    return notes


def report_notes(campaigns: list[Campaign], files: list[str]) -> list[str]:
    """`campaign_notes` of every campaign (rich markup), each after its file's name when there are several: what
    `vehid identify` said under the tables, said again by `vehid report` to whoever the file was handed to."""
    if len(campaigns) == 1:
        return campaign_notes(campaigns[0])
    named = zip(campaigns, files, strict=True)
    return [f"{escape(Path(f).name)}: {note}" for c, f in named for note in campaign_notes(c)]


def plain_text(tables: list, width: int = 160) -> str:
    """Rich tables as plain text (for a report written to a file)."""
    with open(os.devnull, "w") as sink:
        record = Console(record=True, width=width, file=sink)
        for table in tables:
            record.print(table)
        return record.export_text()


def render(campaigns: list[Campaign], files: list[str], fmt: str, published: dict | None = None) -> str:
    """The report as text in format `fmt` (all but 'table', which is printed with rich): JSON is one document per
    campaign with its file and provenance, for every system; the others are the system's own."""
    system = system_of(campaigns, files)
    if fmt == "json":
        docs = [dict(c.to_json(), file=f, provenance=file_provenance(f)) for c, f in zip(campaigns, files, strict=True)]
        return to_json(docs)
    if fmt not in FORMATS or fmt == "table":
        raise InputError(f"unknown format '{fmt}'; expected one of {', '.join(FORMATS)}")
    return system.render(campaigns, files, fmt, published)
