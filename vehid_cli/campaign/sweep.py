"""Sweeps: the Cartesian product of config variations, one campaign file each, shardable for job arrays.

A sweep is planned deterministically from the base config and the `--vary` lists, so every shard of a
job array plans the same campaigns and runs its share (`--shard K/N`: campaigns K-1, K-1+N, ...). A
campaign whose file already holds results of the same resolved config (checksum verified) is skipped; a
damaged file is reported and its campaign run again.

Any number of sweeps and shards may share an output directory. Each campaign is run under its file's lock
(`locking.py`): a campaign another process is running is left for later, then waited for, and skipped if
that process finished it. A file another process rewrote with a different config while this sweep ran is
never overwritten (that would lose its results). `index.csv` is merged, under its own lock, with the
campaigns every sweep into the directory planned.
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import io
import itertools
import json
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from ..config import AnyConfig, Override, load_config
from ..core.errors import InputError, quote
from ..core.files import atomic_path, read_regular
from ..core.locking import Busy, exclusive, lock_path
from .results import campaign_file_digest, config_difference
from .runner import Checkpoint, checkpoint_dir_for


@dataclass(frozen=True)
class Variation:
    """One --vary option: a dotted key and the values it takes (YAML text, parsed by the config loader)."""

    key: str
    values: tuple[str, ...]


@dataclass(frozen=True)
class PlannedCampaign:
    index: int
    overrides: tuple[str, ...]  # the --set lines that make this campaign
    config: AnyConfig
    path: Path


def split_top_level(text: str) -> list[str]:
    """Split on commas that are not inside brackets or braces ("a,[1,2],b" -> ["a", "[1,2]", "b"])."""
    parts, depth, current = [], 0, []
    for ch in text:
        if ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        if ch == "," and depth == 0:
            parts.append("".join(current))
            current = []
        else:
            current.append(ch)
    parts.append("".join(current))
    return [p.strip() for p in parts]


def parse_vary(items: Sequence[str]) -> list[Variation]:
    """Parse `KEY=V1,V2,...` options."""
    out = []
    for item in items:
        key, sep, values = item.partition("=")
        key = key.strip()
        parsed = split_top_level(values) if sep else []
        if not key or not sep or not all(parsed):
            raise InputError(f"--vary expects dotted.key=value1,value2,..., got '{item}'")
        if any(v.key == key for v in out):
            raise InputError(f"--vary {key} is given twice")
        out.append(Variation(key, tuple(parsed)))
    if not out:
        raise InputError("a sweep needs at least one --vary dotted.key=value1,value2")
    return out


def parse_shard(text: str | None) -> tuple[int, int]:
    """`K/N` -> (K, N) with 1 <= K <= N; None -> (1, 1)."""
    if text is None:
        return 1, 1
    m = re.fullmatch(r"\s*([0-9]{1,9})\s*/\s*([0-9]{1,9})\s*", text)  # a billion shards at most
    if not m or not (1 <= int(m.group(1)) <= int(m.group(2))):
        raise InputError(f"--shard expects K/N with 1 <= K <= N (at most 9 digits each), got '{text}'")
    return int(m.group(1)), int(m.group(2))


def _slug(key: str, value: str) -> str:
    """`level-0.1` for noise.level=0.1; a long value is cut and told apart by a hash, so that a campaign's file name
    stays within the file system's 255 bytes."""
    name = key.split(".")[-1]
    slug = f"{name}-{re.sub(r'[^A-Za-z0-9.+-]+', '-', value).strip('-') or 'x'}"
    if len(slug) > 60:
        slug = f"{slug[:50]}-{hashlib.sha256(f'{key}={value}'.encode()).hexdigest()[:8]}"
    return slug


def plan_sweep(config_path: str | Path, base_overrides: Sequence[str], variations: Sequence[Variation], out_dir: Path):
    """Every campaign of the sweep, validated up front (a bad value fails before anything runs)."""
    planned = []
    for index, combo in enumerate(itertools.product(*(v.values for v in variations))):
        overrides = tuple(f"{v.key}={value}" for v, value in zip(variations, combo, strict=True))
        named = [Override(o, f"--vary {o}") for o in overrides]  # an error names the --vary value
        config = load_config(config_path, list(base_overrides) + named)
        name = "_".join(_slug(v.key, value) for v, value in zip(variations, combo, strict=True))
        if len(name.encode()) > 200:  # many varied keys: the file name stays within the file system's limit
            name = f"{name[:150]}-{hashlib.sha256(name.encode()).hexdigest()[:12]}"
        planned.append(PlannedCampaign(index, overrides, config, out_dir / f"{name}.h5"))
    names = [p.path.name for p in planned]
    if len(set(names)) != len(names):
        raise InputError("two campaigns of this sweep would share a file name; vary distinct keys")
    return planned


def shard_of(planned: Sequence[PlannedCampaign], shard: tuple[int, int]) -> list[PlannedCampaign]:
    """The campaigns of shard K/N of a plan: K-1, K-1+N, ..."""
    k, n = shard
    return [p for p in planned if p.index % n == k - 1]


def campaign_attrs(variations: Sequence[Variation], planned: PlannedCampaign) -> dict[str, str]:
    """What a sweep's campaign file records of the sweep: the varied keys (JSON) and its own --vary values."""
    return {"sweep_vary": json.dumps([v.key for v in variations]), "sweep_overrides": " ".join(planned.overrides)}


def stored_digest(path: Path) -> str | None:
    """The config digest a finished campaign file records, or None if there is no readable one."""
    try:
        return campaign_file_digest(path)
    except InputError:
        return None


def file_state(path: Path) -> tuple[str | None, str | None]:
    """(config digest, None) of a whole campaign file; (None, None) without a file; (None, reason) for a
    damaged one."""
    if not path.exists():
        return None, None
    try:
        return campaign_file_digest(path), None
    except InputError as exc:
        return None, exc.detail


INDEX_COLUMNS = ["index", "file", "overrides", "config_sha256"]


INDEX_LIMIT = 16 << 20  # bytes of an index.csv (a row per campaign: a sweep of 100 000 campaigns fits)


def read_index(path: Path) -> list[dict[str, str]]:
    """The rows of an index.csv (InputError naming the file if it is not one: not a regular file, not UTF-8 CSV, a
    column missing or empty, a file that is not a plain `.h5` name in the sweep's directory)."""
    source = str(path)
    try:
        text = read_regular(path, INDEX_LIMIT, "sweep index").decode("utf-8")
        rows = list(csv.DictReader(io.StringIO(text, newline="")))
    except FileNotFoundError:
        raise InputError("sweep index not found", source=source) from None
    except (UnicodeDecodeError, csv.Error) as exc:
        raise InputError(f"cannot read the sweep index ({quote(str(exc), 120)[1:-1]})", source=source) from None
    for n, row in enumerate(rows, start=2):
        missing = [c for c in INDEX_COLUMNS if not isinstance(row.get(c), str) or (c == "file" and not row[c])]
        if missing or None in row:
            what = f"no {', '.join(missing)}" if missing else "more cells than columns"
            raise InputError(
                f"not a sweep index: line {n} has {what} (expected the columns {', '.join(INDEX_COLUMNS)})",
                source=source,
            )
        name = row["file"]
        if Path(name).name != name or not name.endswith(".h5") or name.startswith("."):
            raise InputError(f"not a sweep index: line {n} names {quote(name, 80)}, not a campaign file of the "
                             "sweep's directory", source=source)  # fmt: skip
    return rows


def write_index(out_dir: Path, planned: Sequence[PlannedCampaign], log: Callable[[str], None] | None = None) -> Path:
    """index.csv: one row per planned campaign (file, overrides, config digest), merged under a lock with the
    rows other sweeps into the same directory wrote (a planned file replaces its earlier row)."""
    path = out_dir / "index.csv"
    with exclusive(path, wait=True):
        rows: dict[str, list[str]] = {}
        if path.exists():
            try:
                rows = {r["file"]: [r[c] for c in INDEX_COLUMNS] for r in read_index(path)}
            except InputError as exc:
                if log:
                    log(f"warning: {exc}; rewritten")
        for p in planned:
            rows[p.path.name] = [str(p.index), p.path.name, " ".join(p.overrides), p.config.digest()]
        buf = io.StringIO()
        writer = csv.writer(buf)
        writer.writerow(INDEX_COLUMNS)
        writer.writerows(rows.values())
        with atomic_path(path) as tmp:
            tmp.write_text(buf.getvalue())
    return path


@dataclass(frozen=True)
class SweepOutcome:
    """What one process did of its share of a sweep."""

    ran: tuple[PlannedCampaign, ...]  # campaigns this process ran
    skipped: tuple[PlannedCampaign, ...]  # up to date (before, or finished meanwhile by another process)
    conflicts: tuple[PlannedCampaign, ...]  # rewritten meanwhile by another process with another config


def check_no_other_campaigns(planned: Sequence[PlannedCampaign]) -> None:
    """InputError, before any work, if a planned file already holds a campaign of another config (a sweep with
    other settings wrote it): naming the files and the first difference; `--force` overwrites them."""
    others = []
    for p in planned:
        digest, _ = file_state(p.path)
        if digest is not None and digest != p.config.digest():
            diffs = config_difference(p.path, p.config, None)
            others.append(f"{p.path.name} ({diffs[0] if diffs else 'another config'})")
    if others:
        shown = ", ".join(others[:3]) + (f" and {len(others) - 3} more" if len(others) > 3 else "")
        raise InputError(
            f"{len(others)} campaign file(s) here hold other configs: {shown}; choose another -o, or --force to "
            "overwrite them",
            source=str(planned[0].path.parent),
        )


def check_no_conflicts(outcome: SweepOutcome, out_dir: Path) -> None:
    """InputError, after the sweep, if another sweep rewrote some of its files with a different config meanwhile
    (they were not overwritten)."""
    if outcome.conflicts:
        raise InputError(
            f"{len(outcome.conflicts)} campaign file(s) were written meanwhile by another sweep with a different "
            f"config and were not overwritten ({', '.join(p.path.name for p in outcome.conflicts)}); give different "
            "sweeps different output directories",
            source=str(out_dir),
        )


def tidy(path: Path, digest: str) -> None:
    """The campaign file `path` is whole and of the planned config (`digest`): what a kill between its write and its
    clean-up left beside it (its checkpoint, its lock file) is removed under its lock, as the campaign's own rerun
    would (`runner.run_campaign_to_file`); left to the process holding the lock, if one does. Best effort: what is
    not vehid's to remove (a directory or symlink where the lock or checkpoint goes) is left, for the campaign's next
    run to refuse by name, and the finished campaign still counts as done."""
    partial = checkpoint_dir_for(path)
    if not (partial.is_dir() or lock_path(path).exists()):
        return
    with contextlib.suppress(InputError, OSError), exclusive(path):  # (Busy too); released: the lock file goes
        if file_state(path)[0] == digest:
            Checkpoint(partial, "").remove()


def run_sweep(
    planned: Sequence[PlannedCampaign],
    shard: tuple[int, int],
    run_one: Callable[[PlannedCampaign], None],
    on_skip: Callable[[PlannedCampaign], None] | None = None,
    log: Callable[[str], None] | None = None,
) -> SweepOutcome:
    """Run this shard's campaigns that have no up-to-date file, each under its file's lock (`run_one` must
    not take the lock again). Campaigns another process holds are done last, after waiting for it."""
    mine = shard_of(planned, shard)
    at_start = {p.path: file_state(p.path)[0] for p in mine}
    ran, skipped, conflicts, busy = [], [], [], []

    def up_to_date(p: PlannedCampaign) -> bool:
        if file_state(p.path)[0] != p.config.digest():
            return False
        skipped.append(p)
        if on_skip:
            on_skip(p)
        return True

    def attempt(p: PlannedCampaign, wait: bool) -> bool:
        """Run (or skip) one campaign; False if another process holds it and `wait` is not set."""
        if up_to_date(p):
            tidy(p.path, p.config.digest())
            return True
        with contextlib.ExitStack() as stack:
            try:
                stack.enter_context(exclusive(p.path))
            except Busy:
                if not wait:
                    return False
                if log:
                    log(f"{p.path.name}: another process is running it; waiting for it")
                stack.enter_context(exclusive(p.path, wait=True))
            if up_to_date(p):  # finished by the process that held it
                return True
            digest, damage = file_state(p.path)  # what the file holds now that nobody else writes it
            if digest is not None and digest != at_start[p.path]:
                conflicts.append(p)
                if log:
                    log(f"error: {p.path}: another sweep wrote it with a different config while this one ran; "
                        "not overwritten (give different sweeps different output directories)")  # fmt: skip
                return True
            if damage and log:
                log(f"warning: {p.path}: {damage}; running the campaign again")
            run_one(p)
            ran.append(p)
        return True

    for p in mine:
        if not attempt(p, wait=False):
            busy.append(p)
    for p in busy:
        attempt(p, wait=True)
    return SweepOutcome(tuple(ran), tuple(skipped), tuple(conflicts))
