"""Optimizers: one module per algorithm, each registered under its SPEC name."""

from __future__ import annotations

import importlib
from typing import Any

from .base import REGISTRY, Optimizer, OptimizeResult, Problem

# SPEC name -> module: an algorithm's module is imported when it is asked for (lsq pulls in scipy.optimize, which
# a GA campaign need not load).
ALGORITHMS = {
    "ga": "ga", "cpso": "cpso", "abc": "abc", "de": "de", "nelder-mead": "nelder_mead", "lsq": "lsq",
    "hybrid": "hybrid",
}  # fmt: skip
ALGORITHM_MODULES = tuple(ALGORITHMS.values())

__all__ = [
    "ALGORITHMS", "REGISTRY", "OptimizeResult", "Optimizer", "Problem", "algorithm_class", "get_optimizer", "load_all",
]  # fmt: skip


def load_all() -> None:
    """Import every algorithm module, so each registers itself."""
    for module in ALGORITHM_MODULES:
        importlib.import_module(f"{__name__}.{module}")


def algorithm_class(name: str) -> type[Optimizer]:
    """The optimizer class of a SPEC name, importing only its module (KeyError for an unknown name)."""
    if name not in ALGORITHMS:
        raise KeyError(f"unknown algorithm {name!r}; known: {', '.join(sorted(ALGORITHMS))}")
    importlib.import_module(f"{__name__}.{ALGORITHMS[name]}")
    return REGISTRY[name]


def get_optimizer(name: str, population: int = 20, iterations: int = 50, **options: Any) -> Optimizer:
    """An optimizer by its SPEC name (`ga`, `cpso`, `abc`, `de`, `nelder-mead`, `lsq`, `hybrid`)."""
    return algorithm_class(name)(population=population, iterations=iterations, **options)
