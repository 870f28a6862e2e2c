"""HDF5 result files: layout, atomic writes, provenance."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from .data import atomic_path
from .experiment import SimulatedRun
from .models.fullcar import DOF_NAMES
from .provenance import provenance


def write_simulation_h5(path: str | Path, run: SimulatedRun, seed: int) -> None:
    """One simulated run: the road, clean and noisy responses, coordinates, and the resolved config.

    Layout: /t, /road (n, 4); /clean/{acc, disp, q}; /noisy/{acc, disp}; root attributes hold the
    resolved config (YAML), its SHA-256, the noise level, the seed and provenance.
    """
    exp = run.experiment
    with atomic_path(path) as tmp, h5py.File(tmp, "w") as h5:
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
