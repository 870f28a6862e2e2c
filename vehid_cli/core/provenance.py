"""Where a result came from: package versions, git commit, host, time."""

from __future__ import annotations

import datetime
import platform
import subprocess
from functools import lru_cache
from importlib import metadata
from pathlib import Path

from .. import __version__

TRACKED_PACKAGES = ("numpy", "scipy", "numba", "h5py", "pydantic")  # numpy, scipy and numba set the numbers


@lru_cache(maxsize=1)
def git_commit() -> str:
    """The commit of the vehid checkout this code runs from ('unknown' outside a git checkout)."""
    here = Path(__file__).resolve().parent
    try:
        out = subprocess.run(
            ["git", "-C", str(here), "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5, check=True
        )
        commit = out.stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(here), "status", "--porcelain", "--untracked-files=no"],
            capture_output=True, text=True, timeout=5,
        ).stdout.strip()  # fmt: skip
        return commit + ("-dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def ask_early() -> None:
    """What a command would otherwise spawn a process for once it is large, asked now (and cached) while it is small:
    the git commit (the results' provenance) and the processor `platform.uname()` gives (h5py reads it at import:
    `uname -p`). A process spawned by vfork from one of 200 MiB shows those pages a second time in the process tree's
    summed RSS until it has exec'd (the 60 s record's `identify` read 359-396 MiB in one run of three or twelve)."""
    git_commit()
    _ = platform.uname().processor  # cached on the uname result that h5py's import asks for again


def provenance() -> dict[str, str]:
    """Flat string attributes for a results file."""
    info = {
        "vehid_version": __version__,
        "git_commit": git_commit(),
        "host": platform.node(),
        "python": platform.python_version(),
        "created_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
    }
    for name in TRACKED_PACKAGES:
        try:
            info[f"{name}_version"] = metadata.version(name)
        except metadata.PackageNotFoundError:
            pass
    return info
