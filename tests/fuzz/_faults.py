"""A full disk or a read-only folder at a chosen write, for the `diskfull` family (test code, not vehid's).

`install()` wraps `os.open` (a file created), `os.write`, `os.fsync` and `os.mkdir` once per process. While the
environment holds VEHID_FUZZ_FAULT=KIND:OP:ERRNO, every such call of operation OP on a file of kind KIND below the
working directory fails with OSError(ERRNO), as the kernel reports a full disk (ENOSPC, EDQUOT) or a read-only
file system (EROFS) there; without the variable the calls pass through. `typer`'s CliRunner sets the variable for
the one command of an in-process case; a child process gets it with PYTHONPATH naming `_site`, whose
`sitecustomize` installs the same wrappers. The kinds: `lock` (a `.NAME.lock`), `mkdir` (a `.partial` directory),
`stamp` (`campaign.json`), `record` (`run-*.npz`), `campaign` (`*.h5`), `json` (`*.json`), `index` (`index.csv`);
a temporary `.NAME.XXXX.tmp` counts as the file NAME it becomes.
"""

from __future__ import annotations

import os
import re

ENV = "VEHID_FUZZ_FAULT"
SITE = os.path.join(os.path.dirname(os.path.abspath(__file__)), "_site")
_TMP = re.compile(r"\.(.+)\.[A-Za-z0-9_]+\.tmp")
_REAL = {}


def kind_of(path: str) -> str | None:
    name = os.path.basename(str(path))
    if name.startswith(".") and name.endswith(".lock"):
        return "lock"
    m = _TMP.fullmatch(name)
    name = m.group(1) if m else name
    if name.endswith(".partial"):
        return "mkdir"
    if name == "campaign.json":
        return "stamp"
    if name.startswith("run-") and name.endswith(".npz"):
        return "record"
    if name.endswith(".h5"):
        return "campaign"
    if name == "index.csv":
        return "index"
    if name.endswith(".json"):
        return "json"
    return None


def _fault(path, op: str) -> int | None:
    spec = os.environ.get(ENV)
    if not spec:
        return None
    kind, want, code = spec.split(":")
    if want != op or kind_of(path) != kind:
        return None
    here = os.path.realpath(os.getcwd())
    return int(code) if os.path.realpath(str(path)).startswith(here + os.sep) else None


def _fd_path(fd: int) -> str:
    try:
        return os.readlink(f"/proc/self/fd/{fd}")
    except OSError:
        return ""


def _raise(code: int, path) -> None:
    raise OSError(code, os.strerror(code), str(path))


def _open(path, flags, mode=0o777, *, dir_fd=None):
    if flags & os.O_CREAT and (code := _fault(path, "create")):
        _raise(code, path)
    return _REAL["open"](path, flags, mode, dir_fd=dir_fd)


def _write(fd, data):
    if os.environ.get(ENV) and (code := _fault(_fd_path(fd), "write")):
        _raise(code, _fd_path(fd))
    return _REAL["write"](fd, data)


def _fsync(fd):
    if os.environ.get(ENV) and (code := _fault(_fd_path(fd), "fsync")):
        _raise(code, _fd_path(fd))
    return _REAL["fsync"](fd)


def _mkdir(path, mode=0o777, *, dir_fd=None):
    if code := _fault(path, "create"):
        _raise(code, path)
    return _REAL["mkdir"](path, mode, dir_fd=dir_fd)


def install() -> None:
    """Wrap the four calls (once per process)."""
    if _REAL:
        return
    for name, wrapper in (("open", _open), ("write", _write), ("fsync", _fsync), ("mkdir", _mkdir)):
        _REAL[name] = getattr(os, name)
        setattr(os, name, wrapper)
