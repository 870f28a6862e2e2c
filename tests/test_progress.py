"""Progress with the time left: `diagnose` and `design` report their steps through a hook (no UI in the library);
without a terminal (CI logs) each step is one plain stderr line with the time elapsed and about how much is left,
and stdout keeps only the results."""

from __future__ import annotations

import json
import re

import pytest

from tests.conftest import BASE_CONFIG, ROOT, cli
from vehid_cli.core import progress as P
from vehid_cli.core.progress import PlainProgress, eta

SHORT = ["simulation.duration=1.5", "simulation.dt=0.002"]
LINE = re.compile(r"^(?P<verb>\w+) (?P<stage>.+): (?P<unit>[\w-]+) (?P<done>\d+)/(?P<total>\d+) done "
                  r"\((?P<elapsed>[\d.]+) s elapsed(, about (?P<left>\d+) s left)?\)$")  # fmt: skip


def test_eta_is_the_pace_so_far_times_the_steps_left():
    assert eta(10.0, 4, 12) == pytest.approx(20.0)
    assert eta(3.0, 0, 12) is None and eta(3.0, 2, None) is None
    assert eta(5.0, 12, 12) == 0.0


def test_plain_lines_say_the_time_left_until_the_last_step(monkeypatch):
    now = [100.0]
    monkeypatch.setattr(P.time, "monotonic", lambda: now[0])
    lines: list[str] = []
    with PlainProgress("diagnose", "step", lines.append) as bar:
        task = bar.add_task("round 1 candidates", total=4, unit="candidate")
        for k in range(1, 5):
            now[0] += 2.5  # each candidate takes 2.5 s
            bar.update(task, completed=k)
    assert lines == [
        "diagnose round 1 candidates: candidate 1/4 done (2.5 s elapsed, about 8 s left)",
        "diagnose round 1 candidates: candidate 2/4 done (5.0 s elapsed, about 5 s left)",
        "diagnose round 1 candidates: candidate 3/4 done (7.5 s elapsed, about 2 s left)",
        "diagnose round 1 candidates: candidate 4/4 done (10.0 s elapsed)",
    ]


def _progress(stderr: str, verb: str) -> list[re.Match]:
    return [m for m in map(LINE.match, stderr.splitlines()) if m and m["verb"] == verb]


def test_diagnose_without_a_terminal_prints_a_line_per_step_to_stderr(tmp_path):
    data, doc = tmp_path / "run.csv", tmp_path / "d.json"
    sets = [x for s in SHORT for x in ("--set", s)]
    assert cli("simulate", BASE_CONFIG, "-o", data, *sets, "--set", "noise.level=0.05").exit_code == 0
    res = cli("diagnose", BASE_CONFIG, "--data", data, *sets, "--json", doc)
    assert res.exit_code == 0, res.output
    lines = _progress(res.stderr, "diagnose")
    assert [m["stage"] for m in lines[:1]] == ["declared fit"] and lines[0]["unit"] == "fit"
    rounds = [m for m in lines if m["stage"] == "round 1 candidates"]
    total = int(rounds[0]["total"])
    assert total == len(json.loads(doc.read_text())["candidates"]) > 5  # one line per candidate tested
    assert [int(m["done"]) for m in rounds] == list(range(1, total + 1))
    assert all(m["unit"] == "candidate" for m in rounds)
    assert all(m["left"] is not None for m in rounds[:-1]) and rounds[-1]["left"] is None
    assert not _progress(res.stdout, "diagnose") and "elapsed" not in res.stdout  # stdout: the results only
    assert "verdict:" in res.stdout


def test_design_without_a_terminal_prints_its_generations_to_stderr(tmp_path):
    small = [
        "simulation.dt=0.002", "simulation.duration=2.0", "design.duration=[1.5,2.0]", "design.speed_kmh=[10,40]",
        "design.length=[0.05,0.3]", "design.search.population=8", "design.search.iterations=3", "design.search.grid=7",
    ]  # fmt: skip
    res = cli("design", ROOT / "configs" / "gokdag2015" / "design.yaml", *[x for s in small for x in ("--set", s)],
              "--jobs", "1", "--json", tmp_path / "d.json")  # fmt: skip
    assert res.exit_code == 0, res.output
    search = [m for m in _progress(res.stderr, "design") if m["stage"] == "search"]
    assert [(m["unit"], int(m["done"]), int(m["total"])) for m in search] == [("generation", k, 3) for k in (1, 2, 3)]
    assert search[0]["left"] is not None
    assert "elapsed" not in res.stdout
    json.loads((tmp_path / "d.json").read_text())
