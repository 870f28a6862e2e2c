"""An HDF5 file read whole in a child process: whatever its bytes, the HDF5 library never takes vehid down.

HDF5 trusts the metadata it parses. A damaged or crafted file (even one whose vehid checksum was recomputed after
the damage) can make it loop forever (a flipped byte in the attribute storage of the root group hangs the read of
the `kind` attribute), crash the process (a segmentation fault), or allocate what a declared shape asks for. So
the file is parsed in a forked child (`isolated.in_child`) that sends back plain data: every group, attribute and
dataset as Python and NumPy values (`Tree`, `Data`), each size checked against a budget before it is read. A child
that hangs is killed after a timeout, one that crashes is seen by its signal; both are an `InputError` naming the
file. A part the child could not read (an unsupported type, a soft or external link, a value it could not decode) is
kept as `Broken`, and the reader that asks for it gets an InputError naming the part and why.

The tree reads like h5py for what vehid's readers use: `tree.attrs[name]`, `tree["a/b"]`, `name in tree`,
`tree.items()`, `data[()]`, `data.attrs`, `data.shape`.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .errors import InputError
from .isolated import Damaged, in_child

BUDGET = 1 << 30  # bytes of attributes and datasets one file may make us read (a declared shape never exceeds it)
MAX_OBJECTS = 100_000  # groups, datasets and attributes in one file
MAX_DEPTH = 64  # nesting of groups


@dataclass(frozen=True)
class Broken:
    """A part of the file that could not be read as plain data, and why."""

    reason: str


class Attrs(dict):
    """The attributes of a group or dataset; a `Broken` one raises InputError when asked for."""

    where: str = "/"
    source: str = ""

    def __getitem__(self, name):
        value = super().__getitem__(name)
        if isinstance(value, Broken):
            raise InputError(f"attribute '{name}' of {self.where} cannot be read ({value.reason})", source=self.source)
        return value

    def get(self, name, default=None):
        return self[name] if name in self else default

    def items(self):
        return [(k, self[k]) for k in self]

    def values(self):
        return [self[k] for k in self]


class Data:
    """A dataset's values (a NumPy array, strings decoded to str) and its attributes."""

    def __init__(self, array: np.ndarray, attrs: Attrs):
        self.array = array
        self.attrs = attrs

    @property
    def shape(self) -> tuple[int, ...]:
        return self.array.shape

    @property
    def dtype(self):
        return self.array.dtype

    def __len__(self) -> int:
        return len(self.array)

    def __getitem__(self, key):
        return self.array[key]


class Tree:
    """A group: its attributes and members (groups as Trees, datasets as Data, unreadable parts as Broken)."""

    def __init__(self, where: str, source: str, attrs: Attrs, members: dict[str, Any]):
        self.where, self.source, self.attrs, self.members = where, source, attrs, members

    def __contains__(self, path: str) -> bool:
        node: Any = self
        for part in path.strip("/").split("/"):
            if not isinstance(node, Tree) or part not in node.members:
                return False
            node = node.members[part]
        return True

    def __getitem__(self, path: str):
        node: Any = self
        for part in path.strip("/").split("/"):
            if not isinstance(node, Tree):
                raise InputError(f"{node_where(self, path)} is not a group", source=self.source)
            if part not in node.members:
                raise KeyError(f"no '{path}' in {self.where}")
            node = node.members[part]
            if isinstance(node, Broken):
                raise InputError(f"{node_where(self, path)} cannot be read ({node.reason})", source=self.source)
        return node

    def __iter__(self) -> Iterator[str]:
        return iter(self.members)

    def __len__(self) -> int:
        return len(self.members)

    def keys(self):
        return list(self.members)

    def items(self):
        return [(k, self[k]) for k in self.members]

    def __enter__(self) -> Tree:
        return self

    def __exit__(self, *exc) -> None:
        return None


def node_where(tree: Tree, path: str) -> str:
    return f"{tree.where.rstrip('/')}/{path.strip('/')}"


# ------------------------------------------------------------------------------------------ in the child


class _Walk:
    """The child's reading of one file into plain data, within the budget."""

    def __init__(self, budget: int):
        self.budget = budget
        self.objects = 0
        self.seen: set = set()

    def count(self) -> None:
        self.objects += 1
        if self.objects > MAX_OBJECTS:
            raise ValueError(f"more than {MAX_OBJECTS} groups, datasets and attributes")

    def spend(self, shape, dtype) -> Broken | None:
        size = int(np.prod(shape, dtype=float)) * max(int(dtype.itemsize), 1) if shape is not None else 0
        if size > self.budget:
            return Broken(f"it declares {size} bytes, more than such a file holds")
        self.budget -= size
        return None

    def value(self, raw, dtype):
        """Plain data of a value h5py read: strings decoded, unsupported types Broken."""
        import h5py

        if h5py.check_string_dtype(dtype) is not None or dtype.kind == "S":
            if isinstance(raw, np.ndarray):
                flat = [v.decode("utf-8") if isinstance(v, bytes) else str(v) for v in raw.ravel().tolist()]
                return np.array(flat, dtype=object).reshape(raw.shape)
            return raw.decode("utf-8") if isinstance(raw, bytes) else str(raw)
        if dtype.kind not in "biuf" or dtype.names is not None:
            return Broken(f"unsupported type {dtype}")
        return raw

    def attrs(self, obj, where: str, source: str) -> Attrs:
        out = Attrs()
        out.where, out.source = where, source
        for name in list(obj.attrs):
            self.count()
            try:
                aid = obj.attrs.get_id(name)
                broken = self.spend(aid.shape, aid.dtype)
                out[name] = broken if broken is not None else self.value(obj.attrs[name], aid.dtype)
            except Exception as exc:  # noqa: BLE001 - whatever HDF5 or h5py raise for this attribute: kept as Broken
                out[name] = Broken(f"{exc.__class__.__name__}: {exc}"[:200])
        return out

    def dataset(self, ds, where: str, source: str):
        broken = self.spend(ds.shape, ds.dtype)
        if broken is not None:
            return broken
        try:
            value = self.value(ds[()], ds.dtype)
        except Exception as exc:  # noqa: BLE001 - a dataset HDF5 cannot read (filters, damage): kept as Broken
            return Broken(f"{exc.__class__.__name__}: {exc}"[:200])
        if isinstance(value, Broken):
            return value
        return Data(np.asarray(value), self.attrs(ds, where, source))

    @staticmethod
    def token(obj):
        """What tells HDF5 objects apart in one file (its address; a token in newer HDF5)."""
        import h5py

        info = h5py.h5o.get_info(obj.id)
        return getattr(info, "token", None) or getattr(info, "addr", None)

    def group(self, group, where: str, source: str, depth: int) -> Tree:
        import h5py

        if depth > MAX_DEPTH:
            raise ValueError(f"groups nested more than {MAX_DEPTH} deep")
        if depth == 0:
            self.seen.add(self.token(group))
        members: dict[str, Any] = {}
        for name in list(group):
            self.count()
            path = f"{where.rstrip('/')}/{name}"
            link = group.get(name, getlink=True)
            if not isinstance(link, h5py.HardLink):
                members[name] = Broken(f"a {link.__class__.__name__}, not data stored in the file")
                continue
            obj = group[name]
            token = self.token(obj)
            if token in self.seen:  # a hard link back to a group already read: a cycle, or shared data
                members[name] = Broken("a second link to an object already read")
                continue
            self.seen.add(token)
            if isinstance(obj, h5py.Group):
                members[name] = self.group(obj, path, source, depth + 1)
            elif isinstance(obj, h5py.Dataset):
                members[name] = self.dataset(obj, path, source)
            else:
                members[name] = Broken(f"a {obj.__class__.__name__}")
        return Tree(where, source, self.attrs(group, where, source), members)


def _read(path: str, budget: int) -> Tree:
    """The child's part: the whole file as plain data (a library's exception is the parent's to report)."""
    import h5py

    with h5py.File(path, "r") as h5:
        return _Walk(budget).group(h5, "/", path, 0)


# ------------------------------------------------------------------------------------------ in the parent


def read_tree(path: str | Path, what: str, timeout: float | None = None, budget: int = BUDGET) -> Tree:
    """Every group, attribute and dataset of the HDF5 file `path`, parsed in a child process (module doc);
    InputError naming the file when HDF5 cannot open it, hangs on it or crashes on it."""
    import h5py  # noqa: F401 - imported before the fork: the child imports nothing

    source = str(path)
    size = os.path.getsize(path)
    if timeout is None:
        timeout = 10.0 + size / 10e6
    try:
        return in_child(_read, source, budget, size=size, timeout=timeout)
    except Damaged as exc:
        reason = f"truncated, damaged or not HDF5 ({exc.reason})"
        raise InputError(f"not a readable {what}: {reason}", source=source) from None
