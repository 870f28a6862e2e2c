"""What a campaign identifies from, resolved once: the measured runs (from `--data`, else the config's own), the
other files its results depend on (held-out runs, a stage's run), how results name them and the digest of their
bytes. Built by `DataSource.resolve` where a command starts and passed down; nothing below resolves a path again."""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

DataFiles = str | Path | Sequence[str | Path] | None  # --data: one measured run, several (jointly), or none


def as_paths(data: DataFiles) -> tuple[str, ...]:
    """The data files as a tuple of path strings (empty: none given)."""
    if data is None:
        return ()
    if isinstance(data, (str, Path)):
        return (str(data),)
    return tuple(str(p) for p in data)


@dataclass(frozen=True)
class DataSource:
    """The measured runs a campaign identifies from (`runs`, in order; empty: simulated data) and the other files
    its results depend on (`related`: held-out runs, a stage's own run)."""

    runs: tuple[str, ...] = ()
    related: tuple[str, ...] = field(default=())

    @classmethod
    def resolve(cls, config, data: DataFiles = None) -> DataSource:
        """`--data` (one file or several) wins over the config's runs (`config.data_runs()`); the config names the
        related files (`config.related_runs(measured)`)."""
        if isinstance(data, DataSource):
            return data
        runs = as_paths(data) or tuple(config.data_runs())
        return cls(runs, tuple(config.related_runs(bool(runs))))

    @property
    def simulated(self) -> bool:
        return not self.runs

    @property
    def label(self) -> str | None:
        """How results name the data: the run, or the runs joined by ' + ' (None: simulated)."""
        return " + ".join(self.runs) if self.runs else None

    @property
    def files(self) -> tuple[str, ...]:
        """Every file the results depend on (its bytes enter the campaign key and the digest), in order."""
        return self.runs + self.related

    @cached_property
    def digest(self) -> str | None:
        """SHA-256 of the one file's bytes; of several, the SHA-256 of their digests in order (None: no file)."""
        return files_digest(self.files)


def files_digest(files: Sequence[str | Path]) -> str | None:
    """SHA-256 of a file's bytes (None without one); of several files, the SHA-256 of their digests in order."""
    digests = [hashlib.sha256(Path(f).read_bytes()).hexdigest() for f in files]
    if len(digests) <= 1:
        return digests[0] if digests else None
    return hashlib.sha256(" ".join(digests).encode()).hexdigest()
