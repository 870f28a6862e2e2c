"""The full car as a `System`: the identification task of `identification.py` (bump runs, four body sensors,
f1/f2/wls), with its Cramér–Rao bound."""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

import h5py
import numpy as np
from numpy.typing import NDArray

from .. import __version__
from ..config import Config
from ..crlb import CramerRao
from ..data import write_measurement_csv
from ..experiment import SimulatedRun, build_experiment, run_streams, simulate_measurement
from ..h5io import h5_file
from ..identification import Task, build_task
from ..models.fullcar import DOF_NAMES
from ..optimizers.base import Problem
from ..provenance import provenance
from .base import Box, Simulated, System


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

    @classmethod
    def write_simulation(
        cls, config: Config, target: Path, seed: int, road: Path | None = None, origin: str = ""
    ) -> Simulated:
        """The car on its road (or on `road`, a measurement file's road and time grid), Eq. 15 noise."""
        experiment = build_experiment(config, road_file=road)
        run = simulate_measurement(experiment, run_streams(seed, 0).noise)
        if target.suffix.lower() == ".csv":
            comments = [
                f"vehid {__version__} {origin}".rstrip(),
                f"config sha256 {config.digest()}",
                f"noise level Np = {config.noise.level:g} (Eq. 15), seed {seed}, road from {experiment.road_source}",
            ]
            write_measurement_csv(target, experiment.t, experiment.road, run.acc, run.disp, comments)
        else:
            write_simulation_h5(target, run, seed)
        summary = (
            f"{experiment.t.size} samples at dt = {experiment.dt * 1e3:g} ms, noise Np = {100 * config.noise.level:g} %"
        )
        return Simulated(run, summary)

    def reference(self, run: int) -> dict[str, NDArray]:
        return self.task.reference(run)

    def problem(self, reference: dict[str, NDArray]) -> Problem:
        return self.task.problem(reference)

    def bound(self, at: NDArray | None = None) -> CramerRao:
        return self.task.bound(at)


def write_simulation_h5(path: str | Path, run: SimulatedRun, seed: int) -> None:
    """One simulated run: the road, clean and noisy responses, coordinates, and the resolved config.

    Layout: /t, /road (n, 4); /clean/{acc, disp, q}; /noisy/{acc, disp}; root attributes hold the
    resolved config (YAML), its SHA-256, the noise level, the seed and provenance.
    """
    exp = run.experiment
    with h5_file(path) as h5:
        h5.attrs["kind"] = "vehid.simulation"
        h5.attrs["config_yaml"] = exp.config.to_yaml()
        h5.attrs["config_sha256"] = exp.config.digest()
        h5.attrs["noise_level"] = run.noise_level
        h5.attrs["seed"] = seed
        h5.attrs["road_source"] = exp.road_source
        for key, value in provenance().items():
            h5.attrs[key] = value
        h5.create_dataset("t", data=exp.t).attrs["unit"] = "s"
        h5.create_dataset("road", data=exp.road).attrs["unit"] = "m"
        clean, noisy = h5.create_group("clean"), h5.create_group("noisy")
        for group, acc, disp in ((clean, run.clean.acc, run.clean.disp), (noisy, run.acc, run.disp)):
            group.create_dataset("acc", data=acc).attrs["unit"] = "m/s^2"
            group.create_dataset("disp", data=disp).attrs["unit"] = "m"
        q = clean.create_dataset("q", data=run.clean.q)
        q.attrs["columns"] = np.array(DOF_NAMES, dtype=h5py.string_dtype())
        q.attrs["unit"] = "m (bounce, wheels), rad (roll, pitch)"
