"""Errors the CLI reports in one line, exit status 2: input a user can fix, and an output that cannot be written
(a full disk or quota, a read-only folder: `WriteFailed`, `DiskFull`)."""

from __future__ import annotations

MAX_QUOTE = 200  # characters of a bad value a message quotes


def quote(value, limit: int = MAX_QUOTE) -> str:
    """`repr(value)` cut to `limit` characters (a message never echoes a 100 kB value)."""
    text = repr(value)
    return text if len(text) <= limit else f"{text[: limit - 20]}... ({len(text)} characters)"


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


class WriteFailed(OSError):
    """The system refused to write `path` (a read-only file system, no permission, a name too long, a directory
    where a file belongs, ...): exit status 2, nothing partial left behind."""

    exit_code = 2

    def __init__(self, path, errno_: int, reason: str):
        super().__init__(errno_, reason, str(path))
        self.path = str(path)

    def __str__(self) -> str:
        return f"cannot write {self.path}: {self.strerror}"


class DiskFull(WriteFailed):
    """The file system (or the user's quota) ran out of space writing `path` (ENOSPC, EDQUOT): exit status 2."""

    def __init__(self, path, errno_: int):
        super().__init__(path, errno_, "no space left on device")

    def __str__(self) -> str:
        return f"no space left on device writing {self.path}"
