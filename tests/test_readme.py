"""Every `vehid …` command of README.md runs as written (issue 12).

The commands are taken from the README's fenced `sh` blocks (`\\` continuations joined, `#` comments dropped).
Lines that cannot run here (placeholders, a cluster, `make` targets, other tools) are listed in SKIPPED with the
reason, so a new command is never skipped silently. The fast test checks each command against the CLI (the
subcommand and its options exist, the config and data files it reads exist, its `--set`/`--vary` values are
valid, the `runs/…` files it reads were written by an earlier command); the slow test runs them all, in order,
in a directory laid out like a checkout beside ../shared.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import typer.main

from tests.conftest import ROOT, SHARED, needs_shared, read_png
from vehid_cli.campaign.sweep import parse_shard, parse_vary, plan_sweep
from vehid_cli.cli.app import app
from vehid_cli.config import load_config

README = ROOT / "README.md"

SKIPPED = {
    "make demo": "a make target (creates .venv, runs a demo campaign)",
    "make test": "a make target (the test suite itself)",
    "make paper": "a make target (two full sweeps)",
    "make dampers": "a make target (all of configs/dampers/)",
    "make design": "a make target (three designs and two 30-run campaigns)",
    "dask scheduler --port 8786": "not vehid: starts a Dask scheduler",
    "dask worker tcp://SCHEDULER:8786 --nworkers 8 --nthreads 1": "not vehid: a Dask worker on a cluster host",
    "vehid sweep configs/gokdag2015/base.yaml -o runs/sweep --vary identify.algorithm.name=ga,cpso,abc "
    "--executor dask --scheduler tcp://SCHEDULER:8786": "needs a Dask scheduler (SCHEDULER is a placeholder)",
    "vehid identify configs/gokdag2015/base.yaml --executor dask --scheduler tcp://SCHEDULER:8786": (
        "needs a Dask scheduler (SCHEDULER is a placeholder)"
    ),
    "vehid sweep configs/gokdag2015/base.yaml -o /shared/runs/sweep --jobs 4 --shard $SLURM_ARRAY_TASK_ID/8 "
    "--vary identify.algorithm.name=ga,cpso,abc,hybrid --vary noise.level=0.1,0.2 --vary identify.objective=f1,f2": (
        "a SLURM array job script ($SLURM_ARRAY_TASK_ID, /shared on a cluster)"
    ),
    "vehid sweep … --shard 3/8": "elided arguments (…)",
    "for k in 1 2 3 4; do vehid sweep … --shard $k/4 & done; wait": "elided arguments (…)",
    "vehid report /shared/runs/sweep --format md": "reads the SLURM job's output on a cluster (/shared)",
    "vehid diagnose configs/dampers/brfd_bingham.yaml --data OTHER_RUN.csv --validate HELD_OUT.csv": (
        "placeholder data files (OTHER_RUN.csv, HELD_OUT.csv)"
    ),
}
PLACEHOLDERS = ("…", "SCHEDULER", "$SLURM", "OTHER_RUN.csv", "HELD_OUT.csv", " /shared/")  # /shared: a cluster path
SHELL_SYNTAX = re.compile(r"[|;&<>$`()]")  # a command meant to run as one vehid process has none of these
READS = {"--data", "--road", "--validate", "--published"}  # options whose value is a file the command reads
WRITES = ("-o", "--output", "--json", "--save-config")  # options whose value is a file the command writes


def sh_lines(text: str) -> list[str]:
    """The lines of every ```sh block, `\\` continuations joined, comments dropped, whitespace normalised."""
    out, block, pending = [], False, ""
    for raw in text.splitlines():
        if raw.strip().startswith("```"):
            block = raw.strip() == "```sh"
            continue
        if not block:
            continue
        line = pending + raw.strip()
        if line.endswith("\\"):
            pending = line[:-1] + " "
            continue
        pending = ""
        lexer = shlex.shlex(line, posix=False, punctuation_chars=False)
        lexer.whitespace_split, lexer.commenters = True, "#"
        words = list(lexer)
        if words:
            out.append(" ".join(words))
    return out


def commands() -> tuple[list[str], list[str]]:
    """(the commands to run, the lines skipped)."""
    run, skipped = [], []
    for line in sh_lines(README.read_text()):
        if line.startswith(("vehid ", "python examples/")) and not any(p in line for p in PLACEHOLDERS):
            run.append(line)
        else:
            skipped.append(line)
    return run, skipped


COMMANDS, SKIPPED_FOUND = commands()
CLI = typer.main.get_command(app)


def test_the_readme_has_commands_and_every_skipped_line_is_listed_with_a_reason():
    assert len(COMMANDS) >= 15, COMMANDS  # a sanity check of the extraction
    assert sorted(SKIPPED_FOUND) == sorted(SKIPPED), "README lines skipped but not listed (or listed but gone)"
    assert all(SKIPPED.values())


@pytest.mark.parametrize("line", COMMANDS)
def test_each_command_matches_the_cli_and_its_files_exist(line):
    """Fast: the subcommand and every option exist, no shell syntax, the config and data files read exist, the
    --set overrides load, --vary/--shard parse and the sweep plans, and runs/… inputs come from earlier commands."""
    assert not SHELL_SYNTAX.search(line), f"shell syntax in a README command: {line}"
    words = shlex.split(line)
    if words[0] == "python":  # an example script: it and the config it reads are in the repository
        assert (ROOT / words[1]).is_file() and (ROOT / words[2]).is_file(), line
        return
    name, args = words[1], words[2:]
    assert name in CLI.commands, f"no subcommand {name!r}: {line}"
    params = CLI.commands[name].params
    options = {o for p in params for o in p.opts + p.secondary_opts if o.startswith("-")}
    flags = {o for p in params if getattr(p, "is_flag", False) for o in p.opts}
    positional, values = [], {}
    i = 0
    while i < len(args):
        word = args[i]
        if word.startswith("-"):
            assert word in options, f"`vehid {name}` has no option {word}: {line}"
            if word not in flags:
                values.setdefault(word, []).append(args[i + 1])
                i += 1
        else:
            positional.append(word)
        i += 1

    written_before = set()
    for earlier in COMMANDS[: COMMANDS.index(line)]:
        ew = shlex.split(earlier)
        written_before |= {ew[k + 1] for k, w in enumerate(ew[:-1]) if w in WRITES}
    read = positional + [v for opt in READS for v in values.get(opt, [])]
    for path in read:
        if path.startswith("../shared/"):
            needs_shared(SHARED / path.removeprefix("../shared/"))
        elif path.startswith("configs/"):
            assert (ROOT / path).is_file(), f"{path} is not in the repository: {line}"
        else:
            made = any(path == w or path.startswith(w.rstrip("/") + "/") for w in written_before)  # a file or its dir
            assert path.startswith("runs/") and made, f"{path} is written by no earlier command"

    if name == "report":
        return
    if positional[0].startswith("runs/"):  # a config an earlier command wrote (--save-config): checked when run
        return
    config = ROOT / positional[0]
    overrides = values.get("--set", [])
    load_config(config, overrides)  # the --set keys and values are valid for this config
    if name == "sweep":
        planned = plan_sweep(config, overrides, parse_vary(values.get("--vary", [])), Path("runs"))
        assert planned
        for shard in values.get("--shard", []):
            parse_shard(shard)


@pytest.mark.slow
def test_every_command_runs_as_written(tmp_path):
    """Slow: each command, in README order, by `sh` in a fresh directory laid out like a checkout (configs/,
    an empty runs/) with the shared data at ../shared; each exits 0 and writes what its -o/--json/--plot(s) name
    (read back: tables, JSON, HDF5, figures), or prints its result."""
    shared = needs_shared(SHARED)
    work = tmp_path / "vehid"
    work.mkdir()
    (work / "configs").symlink_to(ROOT / "configs")
    (work / "examples").symlink_to(ROOT / "examples")
    (work / "runs").mkdir()
    (tmp_path / "shared").symlink_to(shared)
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}")
    for line in COMMANDS:
        res = subprocess.run(["sh", "-c", line], cwd=work, env=env, capture_output=True, text=True, timeout=1800)
        assert res.returncode == 0, f"{line}\n{res.stdout[-2000:]}\n{res.stderr[-4000:]}"
        assert "Traceback" not in res.stderr
        if " -o " not in f" {line} ":
            assert res.stdout.strip(), f"nothing printed by: {line}"  # e.g. the report's tables
        words = shlex.split(line)
        for k, word in enumerate(words[:-1]):
            if word in (*WRITES, "--plot", "--plots", "--html"):
                check_output(work / words[k + 1], line)


def check_output(path: Path, line: str) -> None:
    """What a command wrote, read: tables, JSON, HDF5, figures, directories of them."""
    assert path.exists(), f"{path.name} not written by: {line}"
    if path.is_dir():
        files = sorted(path.iterdir())
        assert files, f"{path.name} is empty after: {line}"
        for f in files:
            if f.suffix in (".png", ".h5"):
                check_output(f, line)
    elif path.suffix == ".png":
        read_png(path)
    elif path.suffix == ".json":
        assert json.loads(path.read_text()), line
    elif path.suffix == ".html":  # one self-contained page: tables and embedded figures
        page = path.read_text(encoding="utf-8")
        assert "<table" in page and 'src="data:image/png;base64,' in page, line
    elif path.suffix == ".h5":
        with h5py.File(path, "r") as h5:
            assert "config_yaml" in h5.attrs and len(h5) > 0, line
    elif path.suffix == ".csv":
        table = np.genfromtxt(
            [r for r in path.read_text().splitlines() if not r.startswith("#")], delimiter=",", names=True
        )
        assert table.dtype.names[0] == "t" and table.size > 100 and np.isfinite(table["t"]).all(), line
    elif path.suffix == ".mf4":
        from asammdf import MDF

        with MDF(path) as mdf:
            assert len(mdf.channels_db) > 4 and mdf.get("road1").samples.size > 100, line
    elif path.suffix == ".yaml":
        assert load_config(path), line
    else:
        assert path.suffix == ".md" and path.read_text().count("|") > 10, line
