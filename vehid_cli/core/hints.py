"""Did-you-mean hints for a name a user mistyped (a key, a channel, a unit, a model): the closest known name, or the
one that differs in case only. One rule for every message of the package; each message keeps its own wording."""

from __future__ import annotations

import difflib
from collections.abc import Iterable


def closest(name: str, known: Iterable[str], cutoff: float = 0.6) -> str | None:
    """The closest of `known` to `name` (difflib's ratio at least `cutoff`), else one equal but for case, else None."""
    known = list(known)
    close = difflib.get_close_matches(name, known, n=1, cutoff=cutoff)
    if close:
        return close[0]
    lower = {k.lower(): k for k in known}
    return lower.get(name.lower())


def did_you_mean(name: str, known: Iterable[str]) -> str:
    """The hint " (did you mean 'X'?)" for X the closest of `known`, else ''."""
    match = closest(name, known)
    return f" (did you mean '{match}'?)" if match else ""
