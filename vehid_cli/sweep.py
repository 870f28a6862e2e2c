"""Sweeps: the Cartesian product of config variations, one campaign file each, shardable for job arrays.

A sweep is planned deterministically from the base config and the `--vary` lists, so every shard of a
job array plans the same campaigns and runs its share (`--shard K/N`: campaigns K-1, K-1+N, ...). A
campaign whose file already holds results of the same resolved config is skipped.
"""

from __future__ import annotations

import csv
import io
import itertools
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import h5py

from .config import Config, load_config
from .data import atomic_path
from .errors import InputError


@dataclass(frozen=True)
class Variation:
    """One --vary option: a dotted key and the values it takes (YAML text, parsed by the config loader)."""

    key: str
    values: tuple[str, ...]


@dataclass(frozen=True)
class PlannedCampaign:
    index: int
    overrides: tuple[str, ...]  # the --set lines that make this campaign
    config: Config
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
    m = re.fullmatch(r"\s*(\d+)\s*/\s*(\d+)\s*", text)
    if not m or not (1 <= int(m.group(1)) <= int(m.group(2))):
        raise InputError(f"--shard expects K/N with 1 <= K <= N, got '{text}'")
    return int(m.group(1)), int(m.group(2))


def _slug(key: str, value: str) -> str:
    name = key.split(".")[-1]
    value = re.sub(r"[^A-Za-z0-9.+-]+", "-", value).strip("-") or "x"
    return f"{name}-{value}"


def plan_sweep(config_path: str | Path, base_overrides: Sequence[str], variations: Sequence[Variation], out_dir: Path):
    """Every campaign of the sweep, validated up front (a bad value fails before anything runs)."""
    planned = []
    for index, combo in enumerate(itertools.product(*(v.values for v in variations))):
        overrides = tuple(f"{v.key}={value}" for v, value in zip(variations, combo, strict=True))
        config = load_config(config_path, list(base_overrides) + list(overrides))
        name = "_".join(_slug(v.key, value) for v, value in zip(variations, combo, strict=True))
        planned.append(PlannedCampaign(index, overrides, config, out_dir / f"{name}.h5"))
    names = [p.path.name for p in planned]
    if len(set(names)) != len(names):
        raise InputError("two campaigns of this sweep would share a file name; vary distinct keys")
    return planned


def stored_digest(path: Path) -> str | None:
    """The config digest a finished campaign file records, or None if there is no readable one."""
    try:
        with h5py.File(path, "r") as h5:
            return str(h5.attrs.get("config_sha256"))
    except (OSError, KeyError):
        return None


def write_index(out_dir: Path, planned: Sequence[PlannedCampaign]) -> Path:
    """index.csv: one row per planned campaign (file, overrides, config digest). Same for every shard."""
    buf = io.StringIO()
    writer = csv.writer(buf)
    writer.writerow(["index", "file", "overrides", "config_sha256"])
    for p in planned:
        writer.writerow([p.index, p.path.name, " ".join(p.overrides), p.config.digest()])
    path = out_dir / "index.csv"
    with atomic_path(path) as tmp:
        tmp.write_text(buf.getvalue())
    return path


def run_sweep(
    planned: Sequence[PlannedCampaign],
    shard: tuple[int, int],
    run_one: Callable[[PlannedCampaign], None],
    on_skip: Callable[[PlannedCampaign], None] | None = None,
) -> list[PlannedCampaign]:
    """Run this shard's campaigns that have no up-to-date file; return those that ran."""
    k, n = shard
    ran = []
    for p in planned:
        if p.index % n != k - 1:
            continue
        if p.path.exists() and stored_digest(p.path) == p.config.digest():
            if on_skip:
                on_skip(p)
            continue
        run_one(p)
        ran.append(p)
    return ran
