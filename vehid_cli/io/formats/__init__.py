"""Logger file formats, one module each (`csv`, `mdf4`, `mat`, `hdf5`), found by suffix.

Each module holds one format's reader and writer and registers it (`base.register`); importing this package imports
every module in it, so adding a format is adding a module here and nothing else. `FORMATS` maps a suffix to its
format, `SUFFIXES` to its format's name, both in the order messages list them; `base.py` states the contract.
"""

from __future__ import annotations

import importlib
import pkgutil

from .base import FORMATS, SUFFIXES, LoggerFormat, Raw, own_time_name, register, writable

__all__ = ["FORMATS", "SUFFIXES", "LoggerFormat", "Raw", "own_time_name", "register", "writable"]

for _module in pkgutil.iter_modules(__path__):
    if _module.name != "base" and not _module.name.startswith("_"):
        importlib.import_module(f"{__name__}.{_module.name}")  # each format registers itself
