"""core/allocator.py: freed working memory is reused, not faulted in again on every model evaluation."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# An evaluation's allocation pattern (the sensitivities' drive, lanes, projections: blocks of 1-2 MB freed in another
# order than allocated), 50 times, counting the page faults; argv[1] == "1": with keep_freed_memory first.
PATTERN = """
import resource, sys
import numpy as np
if sys.argv[1] == "1":
    from vehid_cli.core.allocator import keep_freed_memory
    assert keep_freed_memory()
def evaluation():
    a = np.empty(3000 * 84); a.fill(1)
    b = np.empty(3000 * 70); b.fill(1)
    c = np.empty(3000 * 40); c.fill(1)
    del a
    d = np.empty(3000 * 48); d.fill(1)
    del b, c
    e = np.empty(3000 * 40); e.fill(1)
    return d.sum() + e.sum()
evaluation()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(50):
    evaluation()
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def faults(keep: bool) -> int:
    """Minor page faults of the pattern in a fresh interpreter (the package not imported unless `keep`)."""
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", PATTERN, "1" if keep else "0"], capture_output=True, text=True,
                         env=env, check=True)  # fmt: skip
    return int(out.stdout.split()[-1])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_freed_blocks_of_a_few_mb_are_reused_without_page_faults():
    """With glibc's defaults the pattern faults its pages in again on every evaluation (~50 000 faults measured);
    with the thresholds raised the heap keeps them: at most a tenth as many."""
    default, kept = faults(False), faults(True)
    assert default > 50 * 100, default  # the default really re-faults (else this test could not fail)
    assert kept < default / 10, (kept, default)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt")
def test_a_long_record_hands_freed_memory_back():
    """After hand_back_freed_memory (a long record's Experiment sets it) the same pattern faults its pages in again:
    freed blocks of a few MB go back to the system instead of staying mapped (at least half the default's faults)."""
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    pattern = PATTERN.replace(
        "    assert keep_freed_memory()",
        "    from vehid_cli.core.allocator import hand_back_freed_memory\n"
        "    assert keep_freed_memory() and hand_back_freed_memory()",
    ).replace("3000 *", "30000 *")  # blocks of 10-20 MB: above the long record's mmap threshold
    default = int(subprocess.run([sys.executable, "-c", pattern, "0"], capture_output=True, text=True, env=env,
                                 check=True).stdout.split()[-1])  # fmt: skip
    handed = int(subprocess.run([sys.executable, "-c", pattern, "1"], capture_output=True, text=True, env=env,
                                check=True).stdout.split()[-1])  # fmt: skip
    kept = int(subprocess.run([sys.executable, "-c", pattern.replace(" and hand_back_freed_memory()", ""), "1"],
                              capture_output=True, text=True, env=env, check=True).stdout.split()[-1])  # fmt: skip
    assert kept < default / 10, (kept, default)  # 64 MiB kept: the 10-20 MB blocks are reused
    assert handed > default / 2, (handed, default)  # handed back: faulted in again like glibc's defaults


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc_trim")
def test_a_phase_hands_its_freed_pages_back_only_once_a_long_record_is_loaded():
    """release_if_handing_back trims glibc's heaps (malloc_trim) only after hand_back_freed_memory (a long record
    loaded): a short record's freed memory stays for reuse. Run in a fresh process: the thresholds are the process's."""
    script = (
        "from vehid_cli.core import allocator as a\n"
        "before = a.release_if_handing_back()\n"
        "a.hand_back_freed_memory()\n"
        "print(before, a.release_if_handing_back())\n"
    )
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True, env=env)
    assert out.stdout.split() == ["False", "True"]
