"""Reports of campaign files: tables in several formats and figures."""

from __future__ import annotations

import csv
import io
from pathlib import Path

from ..campaign import Campaign
from ..errors import InputError
from ..results import CAMPAIGN_KIND, campaign_json, read_campaign_h5, to_json

FORMATS = ("table", "md", "csv", "latex", "json")


def is_campaign_file(path: Path) -> bool:
    import h5py

    try:
        with h5py.File(path, "r") as h5:
            return h5.attrs.get("kind") == CAMPAIGN_KIND
    except OSError:
        return False


def collect(paths: list[Path]) -> tuple[list[Campaign], list[str]]:
    """Read campaign files; a directory contributes the campaign files in it (other .h5 files are skipped)."""
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


def load_published(path: Path) -> dict:
    """Published reference values (e.g. configs/gokdag2015/paper_tables.yaml) to set beside ours."""
    import yaml

    try:
        doc = yaml.safe_load(Path(path).read_text())
    except (OSError, yaml.YAMLError) as exc:
        raise InputError(f"cannot read published values ({exc.__class__.__name__})", source=str(path)) from None
    if not isinstance(doc, dict) or not isinstance(doc.get("tables"), list):
        raise InputError("expected a mapping with a 'tables' list", source=str(path), key="tables")
    return doc


def render(campaigns: list[Campaign], files: list[str], fmt: str, published: dict | None = None) -> str:
    """The report as text in format `fmt` (all but 'table', which is printed with rich)."""
    from . import tables

    if fmt == "md":
        return tables.markdown(campaigns, published)
    if fmt == "latex":
        return tables.latex(campaigns, published)
    if fmt == "json":
        docs = [dict(campaign_json(c), file=f) for c, f in zip(campaigns, files, strict=True)]
        return to_json(docs)
    if fmt == "csv":
        buf = io.StringIO()
        writer = csv.writer(buf, lineterminator="\n")
        writer.writerow(tables.CSV_COLUMNS)
        writer.writerows(tables.csv_rows(campaigns, files))
        return buf.getvalue()
    raise InputError(f"unknown format '{fmt}'; expected one of {', '.join(FORMATS)}")
