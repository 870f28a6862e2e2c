"""Optimizers: one module per algorithm, each registered under its SPEC name."""

from __future__ import annotations

import importlib
from typing import Any

from .base import REGISTRY, Optimizer, OptimizeResult, Problem

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


def get_optimizer(name: str, population: int = 20, iterations: int = 50, **options: Any) -> Optimizer:
    """An optimizer by its SPEC name (`ga`, `cpso`, `abc`, `de`, `nelder-mead`, `lsq`, `hybrid`)."""
    load_all()
    if name not in REGISTRY:
        raise KeyError(f"unknown algorithm {name!r}; known: {', '.join(sorted(REGISTRY))}")
    return REGISTRY[name](population=population, iterations=iterations, **options)
