"""Errors the CLI reports in one line, exit status 2: input a user can fix, and an output that cannot be written
(a full disk or quota, a read-only folder: `WriteFailed`, `DiskFull`)."""

from __future__ import annotations

import re

QUOTED = 200  # characters of a user's value an error message quotes at most
MESSAGE = 2000  # characters of a whole message at most (a message lists choices, never a file's content)


def clip(text: object, limit: int = QUOTED) -> str:
    """`text` as one line of at most about `limit` characters: a long value (a 100 kB string, a huge list, a
    library's message quoting a whole file) is cut, saying how long it was, so that an error message quoting it
    stays one readable paragraph."""
    try:
        text = str(text).replace("\n", " ")
    except ValueError:  # an integer of more digits than Python prints
        return "(a number too long to print)"
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... ({len(text)} characters)"


def _clip_middle(text: str, limit: int = QUOTED) -> str:
    """A long file name or option clipped in the middle: its start and its end (the file's own name) are kept."""
    if len(text) <= limit:
        return text
    half = limit // 2
    return f"{text[:half]}...{text[-half:]} ({len(text)} characters)"


_LONG_QUOTE = re.compile(rf"'([^'\n]{{{QUOTED + 1},}})'")


def _clip_quotes(message: str) -> str:
    """Each quoted value ('...') of a message clipped to QUOTED characters, then the whole to MESSAGE."""
    message = _LONG_QUOTE.sub(lambda m: f"'{m.group(1)[:QUOTED]}...' ({len(m.group(1))} characters)", message)
    return message if len(message) <= MESSAGE else f"{message[:MESSAGE]}... ({len(message)} characters)"


def quote(value, limit: int = QUOTED) -> str:
    """`repr(value)` clipped to about `limit` characters (a message never echoes a 100 kB value)."""
    try:
        text = repr(value)
    except ValueError:  # an integer of more digits than Python prints
        return "(a number too long to print)"
    return clip(text, limit)


class InputError(Exception):
    """Bad input. The message names the file, the key or column, and what was expected. The source, the key and
    the message are clipped (`clip`): whatever a user's input holds, the message stays a paragraph."""

    exit_code = 2

    def __init__(self, message: str, *, source: str | None = None, key: str | None = None):
        source = None if source is None else _clip_middle(str(source))
        key = None if key is None else clip(key, QUOTED)
        message = _clip_quotes(str(message))
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
