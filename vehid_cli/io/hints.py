"""Did-you-mean hints for a name a user mistyped (a channel, a unit, a variable): one rule for every message of the
io layer, so that a misspelt name in any logger file reads the same."""

from __future__ import annotations

import difflib
from collections.abc import Collection


def did_you_mean(name: str, known: Collection[str]) -> str:
    """The hint " (did you mean 'X'?)" for X the closest of `known` (or the one that differs in case only), else ''."""
    close = difflib.get_close_matches(name, list(known), n=1, cutoff=0.6)
    if not close:
        lower = {k.lower(): k for k in known}
        close = [lower[name.lower()]] if name.lower() in lower else []
    return f" (did you mean '{close[0]}'?)" if close else ""
