"""`vehid report --html`: one self-contained page to hand on (SPEC section 6). The same tables as the terminal
report (the system's own builders, rendered generically from their rich tables), the figures embedded as base64 PNG,
the provenance of every campaign file, and for measured data the verdict on the fit and the checks of each channel.
No script, no external URL: the page reads offline and prints as it shows."""

from __future__ import annotations

import base64
import hashlib
import html
import tempfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from rich.console import Group
from rich.errors import MarkupError
from rich.table import Table
from rich.text import Text

from .. import __version__
from ..core.errors import InputError
from ..core.files import atomic_path
from ..core.provenance import provenance
from ..identify.records import Campaign
from .campaigns import campaign_notes, file_provenance, rich_tables
from .diagnose_plots import plot_diagnosis
from .diagnosis import diagnosis_tables
from .figures import write_plots

STYLE = """
body { font-family: system-ui, -apple-system, 'Segoe UI', Roboto, sans-serif; margin: 2em auto; max-width: 1200px;
       padding: 0 1em; color: #1a1a1a; line-height: 1.45; }
h1 { font-size: 1.6em; border-bottom: 2px solid #444; padding-bottom: .2em; }
h2 { font-size: 1.3em; margin-top: 2em; border-bottom: 1px solid #aaa; }
h3 { font-size: 1.05em; margin-top: 1.4em; }
table { border-collapse: collapse; margin: .8em 0; font-size: .9em; }
caption { text-align: left; font-weight: bold; padding: .3em 0; caption-side: top; }
th, td { border: 1px solid #bbb; padding: .25em .6em; }
th { background: #eee; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
p.caption { font-size: .85em; color: #444; margin-top: -.4em; }
figure { margin: 1.2em 0; }
figure img { max-width: 100%; height: auto; border: 1px solid #ddd; }
figcaption { font-size: .85em; color: #444; }
.verdict { font-size: 1.05em; padding: .5em .8em; border-left: 5px solid #2a7; background: #f2fbf5; }
.verdict.bad { border-color: #c33; background: #fdf2f2; }
dl.prov { display: grid; grid-template-columns: max-content auto; gap: .15em 1em; font-size: .85em; }
dl.prov dt { font-weight: bold; }
dl.prov dd { margin: 0; font-family: monospace; word-break: break-all; }
ul.notes li { margin: .3em 0; }
@media print { figure { break-inside: avoid; } }
"""


@dataclass(frozen=True)
class Section:
    """A part of the page: a heading, a verdict line, tables (rich), notes, figures (PNG files) and facts."""

    title: str
    verdict: str | None = None
    verdict_ok: bool = True
    tables: list = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    figures: list[Path] = field(default_factory=list)
    facts: dict[str, object] = field(default_factory=dict)
    facts_title: str = "provenance"


def plain(cell) -> str:
    """A rich table cell or caption as plain text (markup removed)."""
    if cell is None:
        return ""
    if isinstance(cell, Text):
        return cell.plain
    if isinstance(cell, str):
        try:
            return Text.from_markup(cell).plain
        except MarkupError:
            return cell
    return str(cell)


def _numeric(text: str) -> bool:
    head = text.strip().lstrip("±-–+").strip()
    return bool(head) and (head[0].isdigit() or head in ("inf", "nan"))


def table_html(table: Table) -> str:
    """A rich table as an HTML table: its title as the caption, its column headers, every row, its caption below."""
    columns = table.columns
    head = "".join(f"<th>{html.escape(plain(c.header))}</th>" for c in columns)
    cells = [[plain(v) for v in c._cells] for c in columns]
    rows = []
    for i in range(table.row_count):
        tds = []
        for col in cells:
            text = col[i] if i < len(col) else ""
            cls = ' class="num"' if _numeric(text) else ""
            tds.append(f"<td{cls}>{html.escape(text)}</td>")
        rows.append("<tr>" + "".join(tds) + "</tr>")
    caption = f"<caption>{html.escape(plain(table.title))}</caption>" if table.title else ""
    below = f'<p class="caption">{html.escape(plain(table.caption))}</p>' if table.caption else ""
    return f"<table>{caption}<thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table>{below}"


def _tables(items: Iterable) -> list[Table]:
    """Rich tables out of tables and groups of them (other renderables are skipped)."""
    out = []
    for item in items:
        if isinstance(item, Table):
            out.append(item)
        elif isinstance(item, Group):
            out.extend(_tables(item.renderables))
    return out


def figure_html(path: Path) -> str:
    """A PNG embedded as a data URI, captioned with its file name."""
    data = base64.b64encode(Path(path).read_bytes()).decode("ascii")
    name = html.escape(Path(path).name)
    return f'<figure><img src="data:image/png;base64,{data}" alt="{name}"><figcaption>{name}</figcaption></figure>'


def section_html(section: Section) -> str:
    """One section of the page."""
    parts = [f"<h2>{html.escape(section.title)}</h2>"]
    if section.verdict:
        cls = "verdict" if section.verdict_ok else "verdict bad"
        parts.append(f'<p class="{cls}">{html.escape(section.verdict)}</p>')
    parts.extend(table_html(t) for t in _tables(section.tables))
    if section.notes:
        parts.append('<ul class="notes">' + "".join(f"<li>{html.escape(n)}</li>" for n in section.notes) + "</ul>")
    parts.extend(figure_html(p) for p in section.figures)
    if section.facts:
        items = "".join(
            f"<dt>{html.escape(str(k))}</dt><dd>{html.escape(str(v))}</dd>" for k, v in section.facts.items()
        )
        parts.append(f'<h3>{html.escape(section.facts_title)}</h3><dl class="prov">{items}</dl>')
    return "\n".join(parts)


def page(title: str, sections: Sequence[Section]) -> str:
    """The whole page: inline style, no script, no external resource; who made it and when at the foot."""
    made = provenance()
    foot = (
        f"made by vehid {html.escape(__version__)} (commit {html.escape(made['git_commit'])}) on "
        f"{html.escape(made['host'])} at {html.escape(made['created_utc'])}"
    )
    body = "\n".join(section_html(s) for s in sections)
    return (
        '<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
        '<meta name="viewport" content="width=device-width, initial-scale=1">'
        '<link rel="icon" href="data:,">'
        f"<title>{html.escape(title)}</title><style>{STYLE}</style></head>\n"
        f'<body><h1>{html.escape(title)}</h1>\n{body}\n<footer><p class="caption">{foot}</p></footer></body></html>\n'
    )


def checks_table(checks: Sequence[dict]) -> Table | None:
    """The pre-fit checks of the measurement chain (SPEC section 6) that found something (status other than ok), as
    a table; None when every check passed or none ran."""
    found = [ch for ch in checks if ch.get("status") != "ok"]
    if not found:
        return None
    table = Table(title=f"checks of the measurement chain: {len(found)} finding(s) of {len(checks)} checks")
    for col in ("channel", "check", "status", "value", "message"):
        table.add_column(col)
    for ch in found:
        value = ch.get("value")
        shown = f"{value:.3g}" if isinstance(value, (int, float)) and np.isfinite(value) else str(value)
        table.add_row(*(Text(str(ch.get(k, ""))) for k in ("channel", "check", "status")), shown,
                      Text(str(ch.get("message", ""))))  # fmt: skip
    return table


def fit_verdict(c: Campaign) -> tuple[str, bool] | None:
    """One line on a measured-data fit: does the model reach the noise? (None: simulated data.)"""
    if c.data_file is None:
        return None
    s = c.summary
    if not np.isfinite(s.chi2_median):
        return "no residual figure: the noise is unknown", False
    checks = [ch for ch in c.checks if ch.get("status") == "fail"]
    failed = f"; {len(checks)} check(s) failed: the fit may be meaningless" if checks else ""
    if s.model_inadequate:
        worst = ", ".join(f"{n} {v:.3g}" for n, v in c.worst_channels())
        return (
            f"model lacks something: the residual is {s.chi2_median:.3g} times the noise power (an adequate model "
            f"gives at most {s.chi2_limit:.3g}); worst channels (chi² per sample): {worst}{failed}",
            False,
        )
    return f"adequate: the residual is at the noise (chi² per sample {s.chi2_median:.3g}){failed}", not checks


def campaign_sections(campaigns: Sequence[Campaign], files: Sequence[str], figures: dict[str, list[Path]]) -> list:
    """A section per campaign file: its tables, verdict, checks, notes, its figures and its provenance."""
    tables = rich_tables(list(campaigns), list(files))
    per_file = len(tables) == len(campaigns)  # the system gives one table per campaign (else: all in the first)
    out = []
    for i, (c, f) in enumerate(zip(campaigns, files, strict=True)):
        verdict = fit_verdict(c)
        own = [tables[i]] if per_file else (tables if i == 0 else [])
        checks = checks_table(c.checks)
        out.append(Section(
            title=f"{Path(f).name}: {c.system}, {c.objective or 'cost'}, "
            f"{'data ' + c.data_file if c.data_file else 'simulated data'}",
            verdict=None if verdict is None else verdict[0], verdict_ok=True if verdict is None else verdict[1],
            tables=own + ([checks] if checks is not None else []),
            notes=[plain(n) for n in campaign_notes(c)],
            figures=figures.get(f, []),
            facts={"file": f, **file_provenance(f)},
        ))  # fmt: skip
    return out


def assign_figures(paths: Sequence[Path], files: Sequence[str]) -> tuple[dict[str, list[Path]], list[Path]]:
    """The figures that name one campaign file's stem go with it; the rest (a group's) to the shared section."""
    stems = {f: Path(f).stem for f in files}
    own: dict[str, list[Path]] = {f: [] for f in files}
    shared = []
    for p in paths:
        match = [
            f for f, s in stems.items() if p.stem.endswith("_" + s) or f"_{s}_run" in p.stem or f"-{s}-" in p.stem
        ]  # fmt: skip
        if len(match) == 1:
            own[match[0]].append(p)
        else:
            shared.append(p)
    return own, shared


def campaign_page(
    campaigns: Sequence[Campaign], files: Sequence[str], notes: Sequence[str] = (), figures: bool = True
) -> str:
    """The page of `vehid report --html` for campaign files of one system (figures drawn into a temporary
    directory and embedded)."""
    notes = list(notes)
    with tempfile.TemporaryDirectory(prefix="vehid-html-") as tmp:
        try:
            paths = write_plots(list(campaigns), list(files), tmp) if figures else []
        except InputError as exc:  # e.g. a data file moved or changed since the fit: the tables still go out
            paths = []
            notes.append(f"no figures: {exc}")
        own, shared = assign_figures(paths, files)
        sections = campaign_sections(campaigns, files, own)
        if len(sections) == 1:  # one campaign: its group's figures are its own
            one = sections[0]
            sections = [replace(one, figures=shared + one.figures, notes=notes + one.notes)]
        elif shared or notes:
            sections.append(Section(title="figures and notes of the campaigns together", notes=list(notes),
                                    figures=shared))  # fmt: skip
        title = "vehid report: " + ", ".join(Path(f).name for f in files[:4]) + (" ..." if len(files) > 4 else "")
        return page(title, sections)


def sha256_file(path: str | Path) -> str:
    """SHA-256 of a file's bytes ('unreadable: ...' when it cannot be read: the page still says which file)."""
    h = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    except OSError as exc:
        return f"unreadable: {exc.strerror}"
    return h.hexdigest()


def diagnosis_facts(config: str | Path, overrides: Sequence[str], data: Sequence[str | Path],
                    validate: Sequence[str | Path]) -> dict[str, object]:  # fmt: skip
    """Where a diagnosis came from: the config and every run read (with the SHA-256 of their bytes), the overrides,
    vehid's version and commit, the host and the time."""
    facts: dict[str, object] = {"config": str(config), "config_file_sha256": sha256_file(config)}
    if overrides:
        facts["--set"] = " ".join(overrides)
    for kind, files in (("data", data), ("validate", validate)):
        for i, f in enumerate(files, start=1):
            key = kind if len(files) == 1 else f"{kind} {i}"
            facts[key] = str(f)
            facts[f"{key} sha256"] = sha256_file(f)
    return facts | provenance()


def diagnosis_page(result, facts: dict[str, object], stem: str = "diagnose", figures: bool = True) -> str:
    """The page of `vehid diagnose --html`: the verdict, the candidate and before/after tables, what was added, the
    notes and the checks of the measurement chain, the figures of --plots (the channels before and after the loop
    among them) and where it came from."""
    with tempfile.TemporaryDirectory(prefix="vehid-html-") as tmp:
        paths = plot_diagnosis(result, tmp, stem) if figures else []
        steps = [
            f"added {s.effect}: J {s.J_before:.4g} -> {s.J_after:.4g}, validation J {s.validation_J_before:.4g} -> "
            f"{s.validation_J_after:.4g}" for s in result.steps
        ]  # fmt: skip
        checks = checks_table(result.checks)
        section = Section(
            title=f"diagnosis ({result.system}), {result.wall_s:.1f} s", verdict="verdict: " + result.verdict,
            verdict_ok=result.verdict.startswith(("adequate", "found")),
            tables=[diagnosis_tables(result)] + ([checks] if checks is not None else []),
            notes=steps + [f"note: {n}" for n in result.notes] + [f"noise: {result.sigma_source}",
                                                                   f"validation: {result.validation_source}"],
            figures=[Path(p) for p in paths], facts=facts,
        )  # fmt: skip
        return page(f"vehid diagnose: {stem}", [section])


def write_page(path: str | Path, text: str) -> Path:
    """Write the page atomically."""
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
    return path
