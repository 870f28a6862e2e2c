"""Damaged and hostile input (issue 22): every fuzz family of `tests/fuzz` run in this process, seeded and bounded.

`make test` runs CASES cases spread over the families (under a minute); `make test-all` adds the large campaign in
child processes, where a crash or a hang is seen for what it is. Each case must exit 0 or 2, print no traceback,
internal error or warning, and leave nothing behind (`tests.fuzz.Outcome.problems`).
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from tests.fuzz import ROOT, load_families, make_case, run_in_process

FAMILIES = sorted(load_families())
CASES = int(os.environ.get("VEHID_FUZZ_CASES", "300"))  # in make test, over all families
SEED = 20261125


@pytest.mark.parametrize("name", FAMILIES)
def test_hostile_family_exits_0_or_2_cleanly(name, tmp_path):
    per_family = max(1, CASES // max(1, len(FAMILIES)))
    failures = []
    for index in range(per_family):
        folder = tmp_path / f"{index:04d}"
        case = make_case(name, SEED, index, folder)
        outcome = run_in_process(case, folder, timeout=30)
        if outcome.problems:
            failures.append(f"{case.what}: {'; '.join(outcome.problems)}\n{outcome.text[-600:]}")
    assert not failures, f"{len(failures)} of {per_family} cases:\n" + "\n\n".join(failures[:5])


@pytest.mark.slow
def test_large_fuzz_campaign_in_child_processes(tmp_path):
    """Thousands of cases as a user runs them: no exit 1, no traceback, no crash, no hang, nothing left."""
    cmd = [sys.executable, "-m", "tests.fuzz", "--cases", "2000", "--seed", "7", "--jobs", "2", "--keep", str(tmp_path)]
    res = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True)
    assert res.returncode == 0, res.stdout[-4000:] + res.stderr[-2000:]
