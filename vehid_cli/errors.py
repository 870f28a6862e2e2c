"""Input errors: everything a user can fix in their config, data file or options (exit status 2)."""

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
