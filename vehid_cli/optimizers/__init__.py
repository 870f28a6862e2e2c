"""Optimizers: one module per algorithm, each registered under its SPEC name."""

from __future__ import annotations

import importlib

from .base import REGISTRY, Optimizer, OptimizeResult, Problem, get_optimizer

ALGORITHM_MODULES = ("ga", "cpso", "abc", "de", "nelder_mead", "lsq", "hybrid")

__all__ = ["REGISTRY", "OptimizeResult", "Optimizer", "Problem", "get_optimizer", "load_all"]


def load_all() -> None:
    """Import every algorithm module present, so each registers itself."""
    for module in ALGORITHM_MODULES:
        try:
            importlib.import_module(f"{__name__}.{module}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{__name__}.{module}":
                raise
