"""The protocol every result object follows: to JSON, into an HDF5 group and back, and into a checksummed file of its
own (`core.store.save` / `load`).

A result is a frozen dataclass deriving from `Result`. The defaults work field by field, from the field's value
and type hint: a number, a string or a bool is an attribute; an array, or a tuple of numbers or of strings, a
dataset; a nested result a group; a tuple of results a group of numbered groups (00, 01, ...); a mapping of strings
to numbers a group of attributes. `h5_names` renames a field in the file, `h5_omit` and `json_omit` leave fields
out (a field left out of the file needs a default, or a value passed to `read_h5`). A result whose file layout or
JSON is a contract of its own overrides the method, and says so.
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from .jsonio import finite_or_none

if TYPE_CHECKING:  # h5py (30 ms) is loaded by whoever opens the file a result is written to, not with every result
    import h5py


def jsonable(value: Any) -> Any:
    """A value as plain JSON data: results through their own `to_json`, arrays and tuples as lists, numpy scalars
    as Python numbers, non-finite floats as None."""
    if isinstance(value, Result):
        return value.to_json()
    if isinstance(value, Mapping):
        return {str(k): jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return [jsonable(v) for v in value.tolist()]
    if isinstance(value, (bool, np.bool_)):
        return bool(value)
    if isinstance(value, (int, np.integer)):
        return int(value)
    if isinstance(value, (float, np.floating)):
        return finite_or_none(float(value))
    return value


def _is_result_type(hint: Any) -> bool:
    return isinstance(hint, type) and issubclass(hint, Result)


def _text(values) -> tuple[str, ...]:
    return tuple(v.decode() if isinstance(v, bytes) else str(v) for v in values)


class Result:
    """Base of the result types (see the module doc); subclasses are frozen dataclasses."""

    h5_names: ClassVar[Mapping[str, str]] = {}  # field -> its name in the HDF5 group
    h5_omit: ClassVar[tuple[str, ...]] = ()  # fields not stored in HDF5
    json_omit: ClassVar[tuple[str, ...]] = ()  # fields left out of the JSON

    def to_json(self) -> dict:
        """The fields as plain JSON data (strict once written through `core.jsonio`)."""
        return {
            f.name: jsonable(getattr(self, f.name)) for f in dataclasses.fields(self) if f.name not in self.json_omit
        }

    def write_h5(self, group: h5py.Group) -> None:
        """Every field (but `h5_omit`) into `group`, by kind (module doc)."""
        import h5py  # loaded already: `group` is one of its objects (see the import above)

        strings = h5py.string_dtype()
        for f in dataclasses.fields(self):
            if f.name in self.h5_omit:
                continue
            name, value = self.h5_names.get(f.name, f.name), getattr(self, f.name)
            if isinstance(value, Result):
                value.write_h5(group.create_group(name))
            elif isinstance(value, tuple) and value and all(isinstance(v, Result) for v in value):
                sub = group.create_group(name)
                for k, item in enumerate(value):
                    item.write_h5(sub.create_group(f"{k:02d}"))
            elif isinstance(value, Mapping):
                sub = group.create_group(name)
                for key, item in value.items():
                    sub.attrs[str(key)] = item
            elif isinstance(value, (np.ndarray, tuple, list)):
                data = np.asarray(value)
                group.create_dataset(name, data=data.astype(strings) if data.dtype.kind in "UO" else data)
            else:
                group.attrs[name] = value

    @classmethod
    def read_h5(cls, group: h5py.Group, **given: Any):
        """The result `write_h5` wrote into `group` (fields it omitted from `given` or their defaults); KeyError or
        TypeError for a damaged group."""
        hints = typing.get_type_hints(cls)
        values = dict(given)
        for f in dataclasses.fields(cls):
            if f.name in cls.h5_omit or f.name in values:
                continue
            name, hint = cls.h5_names.get(f.name, f.name), hints[f.name]
            values[f.name] = _read_value(group, name, hint)
        return cls(**values)


def _read_value(group: h5py.Group, name: str, hint: Any) -> Any:
    """One field back from `group` by its type hint."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if _is_result_type(hint):
        return hint.read_h5(group[name])
    if origin is tuple and args and _is_result_type(args[0]):
        return tuple(args[0].read_h5(g) for _, g in sorted(group[name].items()))
    if origin is tuple and args and args[0] is str:
        return _text(group[name][()])
    if origin in (dict, Mapping, typing.Mapping) or hint in (dict, Mapping):
        return {k: v.item() if hasattr(v, "item") else v for k, v in group[name].attrs.items()}
    if name in group:  # an array (or a tuple of numbers)
        data = group[name][()]
        return tuple(data.tolist()) if origin is tuple else data
    value = group.attrs[name]
    if hint is bool:
        return bool(value)
    if hint is int:
        return int(value)
    if hint is float:
        return float(value)
    if hint is str:
        return value.decode() if isinstance(value, bytes) else str(value)
    return value.item() if hasattr(value, "item") else value
