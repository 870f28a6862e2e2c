"""Errors the CLI reports in one line: input a user can fix (exit status 2), and a full disk (exit status 1)."""

from __future__ import annotations


class InputError(Exception):
    """Bad input. The message names the file, the key or column, and what was expected."""

    exit_code = 2

    def __init__(self, message: str, *, source: str | None = None, key: str | None = None):
        self.source = source
        self.key = key
        self.detail = message
        parts = []
        if source:
            parts.append(str(source))
        if key:
            parts.append(f"'{key}'")
        prefix = ": ".join(parts)
        super().__init__(f"{prefix}: {message}" if prefix else message)


class DiskFull(OSError):
    """The file system (or the user's quota) ran out of space writing `path` (ENOSPC, EDQUOT): exit status 1."""

    exit_code = 1

    def __init__(self, path, errno_: int):
        super().__init__(errno_, "no space left on device", str(path))
        self.path = str(path)

    def __str__(self) -> str:
        return f"no space left on device writing {self.path}"
