"""Hostile campaign files, checkpoints, sweep folders and full disks (issue 22): the families `campaign_file`,
`checkpoint`, `sweep_folder` and `diskfull`.

The valid inputs are built once (`Baseline`): a finished 2-run campaign of a tiny config (0.5 s of the bump, DE with
4 x 2 evaluations), its `.partial` checkpoint, and a sweep folder of two such campaigns with its index. Each case
copies what it needs, damages it, and runs the command that reads it: `vehid report`, `vehid identify` resuming into
the same `-o`, `vehid sweep` resuming.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import h5py
import numpy as np

from . import ROOT, Case, _faults, baseline, family

CONFIG = str(ROOT / "configs" / "gokdag2015" / "base.yaml")
TINY = [
    "simulation.duration=0.5", "simulation.dt=0.005", "identify.algorithm.name=de",
    "identify.algorithm.population=4", "identify.algorithm.iterations=2", "identify.runs=2",
]  # fmt: skip
SETS = tuple(a for s in TINY for a in ("--set", s))
IDENTIFY = ("identify", CONFIG, *SETS, "--jobs", "1", "-o", "c.h5")
SWEEP = ("sweep", CONFIG, *SETS, "--jobs", "1", "--vary", "noise.level=0.1,0.2", "-o", "sweep")
VERSION = "campaign-v1"  # the baseline's name: a new one when what it holds changes


def _build(root: Path) -> None:
    """c.h5 (finished), c.h5.partial/ (its two runs), sweep/ (two campaigns and index.csv), sweep-partial/ (the
    checkpoint of sweep/level-0.2.h5)."""
    from vehid_cli.campaign.results import write_campaign_h5
    from vehid_cli.campaign.runner import run_campaign, run_campaign_to_file
    from vehid_cli.campaign.sweep import campaign_attrs, parse_vary, plan_sweep, write_index
    from vehid_cli.config import load_config

    root.mkdir(parents=True)
    cfg = load_config(CONFIG, TINY)
    write_campaign_h5(root / "c.h5", run_campaign(cfg, jobs=1, checkpoint_dir=root / "c.h5.partial"))
    variations = parse_vary(["noise.level=0.1,0.2"])
    planned = plan_sweep(CONFIG, TINY, variations, root / "sweep")
    (root / "sweep").mkdir()
    write_index(root / "sweep", planned)
    for p in planned:
        run_campaign_to_file(p.config, p.path, jobs=1, attrs=campaign_attrs(variations, p))
    run_campaign(planned[1].config, jobs=1, checkpoint_dir=root / "sweep-partial")


def _base() -> Path:
    return baseline().get(VERSION, _build)


def _key(*extra: str) -> str:
    """The campaign key of the tiny config (with `extra` overrides) for this checkout (a checkpoint of another
    commit is refused)."""
    from vehid_cli.campaign.runner import campaign_key
    from vehid_cli.config import load_config

    return campaign_key(load_config(CONFIG, TINY + list(extra)))


def _copy(name: str, to: Path) -> Path:
    src = _base() / name
    if src.is_dir():
        shutil.copytree(src, to)
    else:
        shutil.copy(src, to)
    return to


def _restamp(partial: Path, *extra: str) -> None:
    (partial / "campaign.json").write_text(json.dumps({"key": _key(*extra)}))


# ------------------------------------------------------------------------------------------ hostile values


def _hostile_value(rng: np.random.Generator):
    """A value a field should never hold."""
    choices = [
        np.nan, np.inf, -1e308, 0, -1, 2**62, "", "x" * 100_000, "[" * 5000 + "]" * 5000, np.bytes_(b"\xff\xfe\x80"),
        np.arange(7.0), np.array([["a", "b"]], dtype=h5py.string_dtype()), np.zeros((2, 3, 4)), True,
        "{a: &a [x, x], b: &b [*a, *a], c: &c [*b, *b], d: [*c, *c]}", '{"key": [1, 2]}', "not json {",
        np.array([1 + 2j]), "vehid.simulation", "damper", "toy",
    ]  # fmt: skip
    return choices[rng.integers(len(choices))]


def _walk(h5: h5py.File) -> tuple[list[str], list[str]]:
    datasets, groups = [], []
    h5.visititems(lambda n, o: (datasets if isinstance(o, h5py.Dataset) else groups).append(n))
    return datasets, groups


def _replace_dataset(h5: h5py.File, name: str, rng: np.random.Generator) -> str:
    old = h5[name][()]
    del h5[name]
    way = rng.integers(9)
    if way == 0:
        h5[name] = np.asarray(old).astype(str).astype(h5py.string_dtype()) if np.ndim(old) else str(old)
        return f"{name} stored as strings"
    if way == 1:
        h5[name] = np.full(np.shape(old), np.nan) if np.ndim(old) else np.nan
        return f"{name} all NaN"
    if way == 2:
        h5[name] = np.zeros((int(rng.integers(0, 4)),) * int(rng.integers(0, 4)))
        return f"{name} of another shape"
    if way == 3:
        h5.create_dataset(name, shape=(2**34,), dtype="f8", chunks=(1024,))
        return f"{name} declaring 2**34 samples"
    if way == 4:
        h5.create_group(name)
        return f"{name} replaced by a group"
    if way == 5:
        h5[name] = h5py.SoftLink(f"/{name}")
        return f"{name} a soft link to itself"
    if way == 6:
        h5[name] = h5py.ExternalLink("elsewhere.h5", "/x")
        return f"{name} an external link"
    if way == 7:
        h5[name] = np.zeros(3, dtype=[("a", "f8"), ("b", "i4")])
        return f"{name} a compound type"
    return f"{name} removed"


def _tamper_h5(path: Path, rng: np.random.Generator) -> str:
    """One edit of the campaign file's content through HDF5 (the file stays valid HDF5)."""
    with h5py.File(path, "r+") as h5:
        datasets, groups = _walk(h5)
        way = rng.integers(6)
        if way == 0:
            name = sorted(h5.attrs)[rng.integers(len(h5.attrs))]
            if rng.random() < 0.2:
                del h5.attrs[name]
                return f"attribute {name} removed"
            value = _hostile_value(rng)
            h5.attrs[name] = value
            return f"attribute {name} = {str(value)[:40]!r}"
        if way == 1:
            return _replace_dataset(h5, datasets[rng.integers(len(datasets))], rng)
        if way == 2:
            owners = [h5[n] for n in datasets + groups if len(h5[n].attrs)]
            owner = owners[rng.integers(len(owners))]
            name = sorted(owner.attrs)[rng.integers(len(owner.attrs))]
            owner.attrs[name] = _hostile_value(rng)
            return f"attribute {name} of {owner.name} rewritten"
        if way == 3:
            name = groups[rng.integers(len(groups))]
            del h5[name]
            if rng.random() < 0.5:
                h5[name] = np.zeros(3)
            return f"group {name} removed or made a dataset"
        if way == 4:
            where = h5[groups[rng.integers(len(groups))]]
            where["loop"] = h5  # a hard link back to the root: a cycle
            h5["soft"] = h5py.SoftLink("/soft")
            return "a cycle of hard links and a soft-link loop"
        h5.attrs.create("kind", data=np.array(["vehid.campaign"] * 3000, dtype=h5py.string_dtype()))
        return "kind is a 3000-element attribute"


def _flip(path: Path, rng: np.random.Generator) -> str:
    data = bytearray(path.read_bytes())
    k = int(rng.choice([1, 2, 4, 16]))
    for _ in range(k):
        data[int(rng.integers(512, len(data)))] ^= 1 << int(rng.integers(8))
    path.write_bytes(bytes(data))
    return f"{k} byte(s) flipped"


def _seal(path: Path, rng: np.random.Generator) -> str:
    """The checksum after the edit: recomputed (mostly), stripped (a plain HDF5 file), or left stale."""
    from vehid_cli.core.store import USERBLOCK, stamp_checksum

    u = rng.random()
    if u < 0.8:
        stamp_checksum(path)
        return "checksum recomputed"
    if u < 0.9:
        path.write_bytes(path.read_bytes()[USERBLOCK:])
        return "user block stripped"
    return "checksum left stale"


@family("campaign_file")
def campaign_file(rng: np.random.Generator, folder: Path) -> Case:
    target = _copy("c.h5", folder / "c.h5")
    what = _flip(target, rng) if rng.random() < 0.25 else _tamper_h5(target, rng)
    what += "; " + _seal(target, rng)
    u = rng.random()
    if u < 0.6:
        fmt = ("table", "json", "csv", "md")[rng.integers(4)]
        args = ("report", "c.h5", "--format", fmt)
    elif u < 0.8:
        args = ("report", ".")
    else:
        args = IDENTIFY
    return Case("campaign_file", what, args)


# ------------------------------------------------------------------------------------------ checkpoints


def _record_fields(path: Path) -> dict[str, np.ndarray]:
    with np.load(path) as z:
        return {k: z[k] for k in z.files if k != "sha256"}


def _write_record(path: Path, fields: dict) -> None:
    from vehid_cli.identify.records import _digest

    arrays = {k: np.asarray(v) for k, v in fields.items()}
    with open(path, "wb") as fh:
        np.savez(fh, sha256=np.array(_digest(arrays)), **arrays)


def _tamper_record(path: Path, rng: np.random.Generator) -> str:
    """A record whose digest is recomputed after the edit (it passes the checksum: only validation catches it)."""
    fields = _record_fields(path)
    way = rng.integers(8)
    if way == 0:
        fields["estimate"] = np.ones(int(rng.choice([0, 1, 4, 6, 50])))
        what = "estimate of the wrong length"
    elif way == 1:
        fields["index"] = np.array(int(rng.choice([-1, 7, 2**40])))
        what = f"index {int(fields['index'])}"
    elif way == 2:
        name = ("cost", "evaluations", "penalised", "wall_s", "chi2", "truth_cost")[rng.integers(6)]
        fields[name] = np.array(["text"]) if rng.random() < 0.5 else np.zeros((2, 2))
        what = f"{name} of another type or shape"
    elif way == 3:
        fields["estimate"] = np.full_like(fields["estimate"], np.nan if rng.random() < 0.5 else np.inf)
        what = "estimate not finite"
    elif way == 4:
        del fields[("estimate", "index", "cost", "history_cost")[rng.integers(4)]]
        what = "a field removed"
    elif way == 5:
        fields["history_evals"] = np.arange(5)
        what = "history of another length than its costs"
    elif way == 6:
        fields["estimate"] = fields["estimate"].reshape(1, -1)
        what = "estimate 2-D"
    else:
        fields["channel_chi2"] = np.ones(int(rng.integers(1, 40)))
        what = "channel chi2 of another length"
    _write_record(path, fields)
    return what


def _replace_entry(path: Path, rng: np.random.Generator) -> str:
    """The entry at `path` replaced by something that is not a file vehid wrote."""
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    elif path.exists() or path.is_symlink():
        path.unlink()
    way = rng.integers(7)
    if way == 0:
        path.mkdir()
        (path / "inside").write_text("x")
        return f"{path.name} replaced by a directory"
    if way == 1:
        os.mkfifo(path)
        return f"{path.name} replaced by a FIFO"
    if way == 2:
        os.symlink(path.name, path)
        return f"{path.name} a symlink loop"
    if way == 3:
        os.symlink("/dev/zero", path)
        return f"{path.name} a symlink to /dev/zero"
    if way == 4:
        with open(path, "wb") as fh:
            fh.truncate(int(rng.choice([0, 10, 10**10])))
        return f"{path.name} an empty or sparse file"
    if way == 5:
        os.symlink("nowhere", path)
        return f"{path.name} a dangling symlink"
    path.write_bytes(rng.bytes(int(rng.integers(1, 5000))))
    return f"{path.name} random bytes"


def _tamper_stamp(path: Path, rng: np.random.Generator) -> str:
    docs = [
        "[]", "null", '"key"', '{"key": 5}', '{"key": null}', '{"kee": "x"}', "[" * 100_000 + "]" * 100_000,
        '{"key": "' + "k" * 200_000 + '"}', "\xff\xfe", "{", json.dumps({"key": _key(), "extra": [1, 2]}),
    ]  # fmt: skip
    doc = docs[rng.integers(len(docs))]
    path.write_bytes(doc.encode("utf-8", "surrogateescape") if doc != "\xff\xfe" else b"\xff\xfe")
    return f"campaign.json = {doc[:30]!r}"


@family("checkpoint")
def checkpoint(rng: np.random.Generator, folder: Path) -> Case:
    partial = _copy("c.h5.partial", folder / "c.h5.partial")
    _restamp(partial)
    if rng.random() < 0.15:
        _copy("c.h5", folder / "c.h5")  # the finished file beside it: the stale-checkpoint path
    way = rng.integers(9)
    record = partial / f"run-{int(rng.integers(2)):05d}.npz"
    if way in (0, 1):
        what = _tamper_record(record, rng)
    elif way == 2:
        what = _replace_entry(record, rng)
    elif way == 3:
        what = _tamper_stamp(partial / "campaign.json", rng)
    elif way == 4:
        what = _replace_entry(partial / "campaign.json", rng)
    elif way == 5:
        what = "the checkpoint: " + _replace_entry(partial, rng)
    elif way == 6:
        what = _replace_entry(partial / ("foreign" if rng.random() < 0.5 else ".run-00001.npz.abc123.tmp"), rng)
    elif way == 7:
        what = "lock file: " + _replace_entry(folder / ".c.h5.lock", rng)
    else:
        what = "the output: " + _replace_entry(folder / "c.h5", rng)
    args = IDENTIFY
    u = rng.random()
    if u < 0.1:
        args = (*IDENTIFY, "--runs", str(int(rng.choice([2**63, 2**31, 10**9]))))
        what += f"; {args[-2:]}"
    elif u < 0.2:
        args = (*IDENTIFY, "--json", "out.json")
    return Case("checkpoint", what, args)


# ------------------------------------------------------------------------------------------ sweep folders


def _tamper_index(path: Path, rng: np.random.Generator) -> str:
    docs = [
        b"", b"\xff\xfe\x00garbage", b"index,file\n0,a.h5\n", b"a,b,c\n" + b"x" * 200_000 + b",y,z\n",
        b"index,file,overrides,config_sha256\n0,../../etc/passwd,x,y\n", b"\x00" * 100,
        b"index,file,overrides,config_sha256\n" + b'"unterminated\n' * 3,
        b"index,file,overrides,config_sha256\n0,level-0.1.h5\n1\n",
        b"index,file,overrides,config_sha256\n0,sub/dir/x.h5,a,b\n0,level-0.1.h5,a,b,extra,cols\n",
    ]  # fmt: skip
    doc = docs[rng.integers(len(docs))]
    path.write_bytes(doc)
    return f"index.csv = {doc[:30]!r}"


@family("sweep_folder")
def sweep_folder(rng: np.random.Generator, folder: Path) -> Case:
    sweep = _copy("sweep", folder / "sweep")
    victim = sweep / ("level-0.1.h5" if rng.random() < 0.5 else "level-0.2.h5")
    way = rng.integers(7)
    if way == 0:
        what = _tamper_index(sweep / "index.csv", rng)
    elif way == 1:
        what = "index: " + _replace_entry(sweep / "index.csv", rng)
    elif way == 2:
        what = _replace_entry(victim, rng)
    elif way == 3:
        what = _flip(victim, rng) + "; " + _seal(victim, rng)
    elif way == 4:
        what = _tamper_h5(victim, rng) + "; " + _seal(victim, rng)
    elif way == 5:
        partial = sweep / "level-0.2.h5.partial"
        shutil.copytree(_base() / "sweep-partial", partial)
        _restamp(partial, "noise.level=0.2")
        (sweep / "level-0.2.h5").unlink()
        what = "an interrupted campaign's checkpoint"
        if rng.random() < 0.5:
            what += "; " + _replace_entry(partial / f"run-{int(rng.integers(2)):05d}.npz", rng)
    else:
        what = _replace_entry(sweep / (".level-0.1.h5.lock" if rng.random() < 0.5 else "junk.h5"), rng)
    args = SWEEP if rng.random() < 0.6 else ("report", "sweep")
    return Case("sweep_folder", what, args)


# ------------------------------------------------------------------------------------------ a full disk

ERRORS = {"ENOSPC": 28, "EDQUOT": 122, "EROFS": 30, "EACCES": 13}
SCENARIOS = [  # (kind, operation, command, what the folder holds first)
    ("lock", "create", "identify", ""), ("lock", "write", "identify", ""), ("mkdir", "create", "identify", ""),
    ("stamp", "create", "identify", ""), ("stamp", "fsync", "identify", ""),
    ("record", "create", "identify", "one"), ("record", "fsync", "identify", "one"),
    ("record", "fsync", "identify", ""), ("campaign", "create", "identify", "all"),
    ("campaign", "fsync", "identify", "all"), ("json", "fsync", "identify", "file"),
    ("json", "create", "identify", "file"), ("index", "fsync", "sweep", "dir"), ("index", "create", "sweep", "dir"),
    ("lock", "create", "sweep", "dir"), ("lock", "write", "sweep", "index"), ("campaign", "fsync", "sweep", "partial"),
]  # fmt: skip


@family("diskfull")
def diskfull(rng: np.random.Generator, folder: Path) -> Case:
    """A full disk, a quota or a read-only folder at one kind of write of identify or sweep. What a failure may
    keep (finished runs in a checkpoint) is there before the command, so that any new file left is a fault."""
    _faults.install()
    kind, op, command, first = SCENARIOS[rng.integers(len(SCENARIOS))]
    name = list(ERRORS)[rng.integers(len(ERRORS))]
    if command == "identify":
        args = (*IDENTIFY, "--json", "out.json") if kind == "json" or rng.random() < 0.3 else IDENTIFY
        if first in ("one", "all"):
            partial = _copy("c.h5.partial", folder / "c.h5.partial")
            _restamp(partial)
            if first == "one":
                (partial / "run-00001.npz").unlink()
        elif first == "file":
            _copy("c.h5", folder / "c.h5")
    else:
        args = SWEEP
        (folder / "sweep").mkdir()
        if first in ("index", "partial"):
            shutil.copy(_base() / "sweep" / "index.csv", folder / "sweep" / "index.csv")
            shutil.copy(_base() / "sweep" / "level-0.1.h5", folder / "sweep" / "level-0.1.h5")
        if first == "partial":
            shutil.copytree(_base() / "sweep-partial", folder / "sweep" / "level-0.2.h5.partial")
            _restamp(folder / "sweep" / "level-0.2.h5.partial", "noise.level=0.2")
    env = ((_faults.ENV, f"{kind}:{op}:{ERRORS[name]}"), ("PYTHONPATH", _faults.SITE))
    return Case("diskfull", f"{name} at the {op} of the {kind} ({command}, {first or 'fresh'})", args, env)
