"""Figures off-screen (matplotlib's Agg backend), saved atomically as PNG: every figure of the package goes
through `save`, so a failed write leaves no partial file and a full disk is a clean error."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .files import atomic_path  # noqa: E402

DPI = 110


def save(fig, path: str | Path) -> Path:
    """Write `fig` to `path` as PNG atomically and close it; the path written."""
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=DPI, format="png")
    plt.close(fig)
    return path


__all__ = ["plt", "save"]
