"""Strict JSON: every non-finite number becomes null (JSON has no NaN or Infinity), written atomically."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .files import atomic_path


def finite_or_none(value) -> float | None:
    """JSON has no Infinity or NaN: a bound that does not exist (unidentifiable) is null."""
    return None if value is None or not np.isfinite(value) else float(value)


def to_json(doc) -> str:
    """Strict JSON text: every non-finite number anywhere in `doc` becomes null."""

    def clean(x):
        if isinstance(x, dict):
            return {k: clean(v) for k, v in x.items()}
        if isinstance(x, (list, tuple)):
            return [clean(v) for v in x]
        if isinstance(x, float):
            return finite_or_none(x)
        return x

    return json.dumps(clean(doc), indent=2, allow_nan=False)


def write_json(path: str | Path, doc) -> None:
    """`doc` as strict JSON (to_json), written atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(to_json(doc))
