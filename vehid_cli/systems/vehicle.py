"""The full car as a `System`: the identification task of `identification.py` (bump runs, four body sensors,
f1/f2/wls), with its Cramér–Rao bound."""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

from numpy.typing import NDArray

from ..config import Config
from ..crlb import CramerRao
from ..identification import Task, build_task
from ..optimizers.base import Problem
from .base import Box, System


class VehicleSystem(System):
    """The 7-DOF car on its road: run r identifies from the clean responses plus run r's Eq. 15 noise (or from the
    measured responses)."""

    name: ClassVar[str] = "vehicle"
    objective: ClassVar[str] = "f1, f2 or wls (identify.objective)"

    def __init__(self, config: Config, data_file: str | Path | None = None):
        self.task: Task = build_task(config, data_file)
        t = self.task
        self.config = config
        self.box = Box(t.names, t.lower, t.upper, t.nominal, t.truth)
        self.data_file = t.data_file
        self.sigma = t.sigma
        self.sigma_source = t.sigma_source

    @property
    def residual_samples(self) -> int:
        return self.task.residual_samples

    def reference(self, run: int) -> dict[str, NDArray]:
        return self.task.reference(run)

    def problem(self, reference: dict[str, NDArray]) -> Problem:
        return self.task.problem(reference)

    def bound(self, at: NDArray | None = None) -> CramerRao:
        return self.task.bound(at)
