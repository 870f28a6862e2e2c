"""What a logger file format implements, and the registry that finds it by suffix.

A format is one module of `vehid_cli.io.formats` holding one subclass of `LoggerFormat`, registered with
`@register`: its suffixes, a reader and a writer. The package imports every module in it, so adding a format is
adding a module; nothing else names the formats.

- the reader (`LoggerFormat.read`) returns the channels asked for as stored, each a `Raw`: its own time stamps as
  the file holds them (in the file's time unit when they come from a named time column/vector, else seconds), its
  values in the file's unit, and the unit the file declares ('' if none). Converting to SI, checking the stamps
  and putting the channels on one grid is `io.read.read_record`'s, the same for every format;
- the writer (`LoggerFormat.write`) takes the channels already checked and in the units they are written in, each
  with its own strictly increasing time stamps, and writes the whole file atomically (`core.files.atomic_path`, or
  `core.store.h5_file` for HDF5): the target holds its old content or the whole new file.

A MAT or HDF5 file holds one time vector for all channels (`t`, `time` or the one named by `time=`), and a channel
`X` sampled otherwise its own beside it: `t_X` (HDF5: in X's group, `acc/t_X` for `acc/X`; see `own_time_name`).
The helpers below are the ones several formats share: time vectors, missing names, the layout of time vectors.
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from ...core.errors import InputError
from ...core.hints import did_you_mean

TIME_NAMES = ("t", "time", "Time", "TIME", "timestamp", "Timestamp")  # a time column/vector found without `time=`


@dataclass
class Raw:
    """One channel as stored: its own time stamps [s], values, and the unit the file declares ('' if none)."""

    t: NDArray
    y: NDArray
    unit: str = ""
    time: str = ""  # the name of its time column/vector ('' for MDF4 masters and stamps made from a rate)


class LoggerFormat:
    """A logger file format: the suffixes it owns, its reader and its writer (module docstring)."""

    name: ClassVar[str]  # what `SUFFIXES` maps its suffixes to
    suffixes: ClassVar[tuple[str, ...]]  # lower case, with the dot: the files it reads
    writes: ClassVar[tuple[str, ...]] = ()  # the suffixes it writes (a subset of `suffixes`)
    rank: ClassVar[int] = 100  # where its suffixes stand in the lists messages give (lowest first)
    reports_missing_file: ClassVar[bool] = False  # True: its reader says itself that a file is missing

    def read(
        self, path: Path, channels: Mapping[str, str], *, time: str | None, rate: float | None, variable: str | None
    ) -> dict[str, Raw]:
        """The `channels` (our name -> the name in the file) of the file at `path`, as stored. `time` names the
        time column/vector, `rate` [Hz] makes stamps k / rate when the file has none, `variable` names the
        struct/group holding the channels; a format ignores what it has no use for. Every problem a user can fix
        is an InputError naming the file and the channel."""
        raise NotImplementedError

    def read_ahead(self, path: Path) -> None:
        """Read the file at `path` now, to serve its next `read` from memory (`io.read.read_ahead`: a command
        reads its files before it loads the compiled kernels). A format read in this process has nothing to gain:
        the default keeps nothing. Never raises: what cannot be read ahead is read, and reported, by `read`."""

    def forget(self) -> None:
        """Drop what `read_ahead` kept."""

    def write(
        self,
        path: Path,
        runs: Mapping[str, tuple[NDArray, NDArray]],
        names: Mapping[str, str],
        units: Mapping[str, str],
        *,
        start: dt.datetime | None,
        comment: str,
    ) -> None:
        """Write `runs` (our name -> (t [s], values in the unit written)) to `path` atomically, each channel under
        its name in `names` with its unit in `units` ('' for SI); `start` the wall-clock time of t = 0, `comment`
        a comment for people. A name the format cannot hold is an InputError naming the channel."""
        raise NotImplementedError


FORMATS: dict[str, LoggerFormat] = {}  # suffix -> its format, in the order messages list them (`rank`)
SUFFIXES: dict[str, str] = {}  # suffix -> its format's name, in the same order


def register(cls: type[LoggerFormat]) -> type[LoggerFormat]:
    """Class decorator: register a format under its suffixes (a suffix owned twice is a programming error)."""
    fmt = cls()
    for suffix in cls.suffixes:
        if suffix in FORMATS and FORMATS[suffix].name != cls.name:
            raise ValueError(f"suffix {suffix} is claimed by the formats {FORMATS[suffix].name} and {cls.name}")
    entries = [(s, f) for s, f in FORMATS.items() if f.name != cls.name] + [(s, fmt) for s in cls.suffixes]
    FORMATS.clear()
    FORMATS.update(sorted(entries, key=lambda entry: entry[1].rank))  # stable: a format's suffixes in its order
    SUFFIXES.clear()
    SUFFIXES.update((suffix, f.name) for suffix, f in FORMATS.items())
    return cls


def writable() -> list[str]:
    """The suffixes a format writes, in the order of `SUFFIXES`."""
    return [suffix for suffix, fmt in FORMATS.items() if suffix in fmt.writes]


# ------------------------------------------------------------------------------------------ reading


def numeric(values: object, source: str, what: str) -> NDArray:
    """`values` as a float vector; InputError naming `what` when not numeric or not a vector."""
    arr = np.asarray(values)
    if arr.dtype.kind not in "biuf":
        raise InputError(f"{what} is not numeric (type {arr.dtype})", source=source)
    arr = np.squeeze(arr).astype(float)
    if arr.ndim != 1:
        raise InputError(f"{what} has shape {np.shape(values)}; expected a vector", source=source)
    return arr


def missing(what: str, name: str, known: Sequence[str], source: str, key: str | None = None) -> InputError:
    """The error for a name not in the file: the closest present name, and those present."""
    return InputError(
        f"{what} '{name}' is not in the file{did_you_mean(name, known)}; present: {', '.join(known) or 'none'}",
        source=source,
        key=key,
    )


def time_vector(
    time: str | None,
    found: Sequence[str],
    get: Callable[[str], object],
    names: Sequence[str],
    src: str,
    rate: float | None,
    n: int,
) -> tuple[NDArray, str]:
    """The time vector named `time`, else the first of `found`, else k / rate ('' for its name); InputError if
    none."""
    if time is not None:
        if time not in names:
            raise missing("time vector", time, names, src)
        return numeric(get(time), src, f"time vector '{time}'"), time
    if found:
        return numeric(get(found[0]), src, f"time vector '{found[0]}'"), found[0]
    if rate is not None:
        return np.arange(n) / rate, ""
    raise InputError(
        f"no time vector ({' or '.join(TIME_NAMES[:2])}): name it with time=..., or give the rate; present: "
        f"{', '.join(names)}",
        source=src,
    )


def own_time_name(name: str) -> str:
    """The name of the time vector of channel `name` alone in a MAT or HDF5 file: `t_<name>` beside it (HDF5: in
    its group, `acc/t_X` for `acc/X`). A channel without one has the file's common time vector."""
    head, _, leaf = name.strip("/").rpartition("/")
    return f"{head}/t_{leaf}" if head else f"t_{leaf}"


def stamps_of(
    channels: Mapping[str, str],
    names: Sequence[str],
    get: Callable[[str], NDArray],
    common: Callable[[], tuple[NDArray, str]],
) -> dict[str, tuple[NDArray, str]]:
    """Each channel's time vector (our name -> stamps, name): its own (`own_time_name`) if the file has one, else
    the common one, `common()`, read only when a channel needs it."""
    stamps, shared = {}, []
    for ours, theirs in channels.items():
        own = own_time_name(theirs)
        if own in names:
            stamps[ours] = get(own), own
        else:
            if not shared:
                shared.append(common())
            stamps[ours] = shared[0]
    return stamps


# ------------------------------------------------------------------------------------------ writing


def groups(runs: Mapping[str, tuple[NDArray, NDArray]]) -> list[tuple[NDArray, list[str]]]:
    """Channels by their time stamps (identical arrays share a group), in the order first met."""
    found: list[tuple[NDArray, list[str]]] = []
    for ours, (t, _) in runs.items():
        for stamps, members in found:
            if np.array_equal(stamps, t):
                members.append(ours)
                break
        else:
            found.append((t, [ours]))
    return found


def _common(runs: Mapping[str, tuple[NDArray, NDArray]]) -> tuple[NDArray, list[str]]:
    """The group whose stamps the common time vector `t` holds: the highest rate (the first such group)."""

    def rate(group):
        t = group[0]
        return (t.size - 1) / (t[-1] - t[0]) if t.size > 1 else 0.0

    return max(groups(runs), key=rate)  # max keeps the first of equals


def layout(
    runs: Mapping[str, tuple[NDArray, NDArray]], theirs: Mapping[str, str], src: str, fmt: str, reserved: set[str]
) -> tuple[NDArray, dict[str, str]]:
    """MAT/HDF5: the common time vector and, for each channel not sampled at its stamps, its own time vector's
    name; InputError if a name written twice."""
    t, shared = _common(runs)
    own = {ours: own_time_name(theirs[ours]) for ours in runs if ours not in shared}
    taken: dict[str, str] = {n: f"the {fmt} file's '{n}'" for n in reserved}
    for ours in runs:
        for name, what in ((theirs[ours], f"channel '{ours}'"), (own.get(ours), f"the time vector of '{ours}'")):
            if name is None:
                continue
            key = name.strip("/")
            if key in taken:
                raise InputError(f"{what} would be written as '{name}', as is {taken[key]}", source=src)
            taken[key] = what
    return t, own
