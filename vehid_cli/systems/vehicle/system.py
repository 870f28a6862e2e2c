"""The full car as a `System`: the identification task of `identify/task.py` (bump runs, sensors anywhere,
f1/f2/wls), its Cramér–Rao bound, its simulation files, its diagnosis, tables and figures."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

import numpy as np
from numpy.typing import NDArray

from ... import __version__
from ...config import Config
from ...core.errors import InputError
from ...core.progress import ProgressHook
from ...core.provenance import provenance
from ...core.streams import run_streams
from ...diagnose.checks import Checks, check_runs
from ...identify.crlb import CramerRao
from ...identify.experiment import SimulatedRun, build_experiment, simulate_measurement
from ...identify.records import Campaign
from ...identify.source import DataFiles, DataSource
from ...identify.task import JointTask, Task, build_tasks
from ...io.measurement import ROAD_COLUMNS as ROAD
from ...io.measurement import write_csv, write_measurement_csv
from ...io.write import write_record
from ...models.fullcar import DOF_NAMES
from ...models.sensors import UNIT
from ...optimizers.base import Problem
from ..base import Box, Log, Simulated, System

if TYPE_CHECKING:  # the loop is imported by `diagnose` alone: a campaign does not load it
    from ...diagnose.result import Diagnosis


class VehicleSystem(System):
    """The 7-DOF car on its road: run r identifies from the clean channels plus run r's noise (or from the measured
    runs: several are identified jointly, one parameter set for all)."""

    name: ClassVar[str] = "vehicle"
    objective: ClassVar[str] = "f1, f2 or wls (identify.objective)"
    simulation_suffixes: ClassVar[tuple[str, ...]] = (".csv", ".h5", ".hdf5", ".mf4")
    designable: ClassVar[bool] = True
    diagnosis_defaults: ClassVar[tuple[str, ...]] = ("identify.objective=wls", "noise.level=0")  # noise from the data

    def __init__(self, config: Config, source: DataSource | DataFiles = None):
        source = DataSource.resolve(config, source)
        self.task: Task | JointTask = build_tasks(config, source.runs)
        t = self.task
        self.config = config
        self.source = source
        self.box = Box(t.names, t.lower, t.upper, t.nominal, t.truth)
        self.sigma = run_sigma(t)
        self.sigma_source = t.sigma_source
        self._checks: Checks | None = None

    @property
    def channel_names(self) -> tuple[str, ...]:
        return self.task.channel_names

    def residual_channels(self, reference) -> NDArray:
        return self.task.residual_channels(reference)

    def checks(self) -> Checks | None:
        """Every measured channel of every run against the configured car (`diagnose.checks`), computed once."""
        if self.source.simulated:
            return None
        if self._checks is None:
            self._checks = check_runs(self.task.tasks if isinstance(self.task, JointTask) else (self.task,))
        return self._checks

    @classmethod
    def objective_label(cls, config: Config) -> str:
        return config.identify.objective

    @classmethod
    def results_attributes(cls, config: Config) -> dict[str, str]:
        return {"sensors": config.sensors}

    @classmethod
    def diagnose(
        cls, config: Config, data: tuple[str, ...], validate: tuple[str, ...], log: Log | None,
        progress: ProgressHook | None = None,
    ) -> Diagnosis:  # fmt: skip
        """The car's loop (`diagnosis.diagnose`) on one run or several jointly (else the config's data.files)."""
        files = data or config.data_runs()
        if not files:
            raise InputError("diagnose needs --data FILE (the measured run to fit) or data.files", source=config.source)
        if len(validate) > 1:
            raise InputError("the full car takes one --validate run", source=config.source)
        from . import diagnosis  # the loop's machinery (scipy.stats, splines) only for `vehid diagnose`

        return diagnosis.diagnose(
            config,
            files[0] if len(files) == 1 else files,
            validate[0] if validate else None,
            log=log,
            progress=progress,
        )

    @classmethod
    def tables(cls, campaigns: Sequence[Campaign], files: Sequence[str]) -> list:
        from .report import summary_table

        return [summary_table(c) for c in campaigns]

    @classmethod
    def render(cls, campaigns: Sequence[Campaign], files: Sequence[str], fmt: str, published: dict | None) -> str:
        from .report import render

        return render(list(campaigns), list(files), fmt, published)

    @classmethod
    def figures(cls, campaigns: Sequence[Campaign], files: Sequence[str], out_dir: Path) -> list[Path]:
        from .plots import write_campaign_plots

        return write_campaign_plots(campaigns, files, out_dir)

    @classmethod
    def plot_simulation(cls, simulated: Simulated, path: Path) -> None:
        from .plots import plot_responses

        plot_responses(simulated.run, path)

    @property
    def residual_samples(self) -> int:
        return self.task.residual_samples

    @classmethod
    def write_simulation(
        cls, config: Config, target: Path, seed: int, road: Path | None = None, origin: str = ""
    ) -> Simulated:
        """The car on its road (or on `road`, a measurement file's road and time grid) with its sensors' noise:
        CSV (the SPEC's columns for the paper's layout; t, road1..road4 and one column per sensor otherwise), HDF5
        (clean and noisy channels) or MDF4 (one channel per sensor and per road input, SI units)."""
        experiment = build_experiment(config, road_file=road)
        run = simulate_measurement(experiment, run_streams(seed, 0).noise)
        comments = [
            f"vehid {__version__} {origin}".rstrip(),
            f"config sha256 {config.digest()}",
            f"noise {config.noise.describe()}, seed {seed}, road from {experiment.road_source}",
        ]
        suffix = target.suffix.lower()
        if suffix == ".csv":
            layout = experiment.layout
            if config.layout is None:
                write_measurement_csv(target, experiment.t, experiment.road, run.acc, run.disp, comments)
            else:
                names = ["t", *ROAD, *layout.channel_names]
                table = np.column_stack([experiment.t, experiment.road, *(run.channels[f] for f in layout.families)])
                write_csv(target, names, table, comments)
        elif suffix == ".mf4":
            write_simulation_mdf(target, run, comments)
        else:
            write_simulation_h5(target, run, seed)
        summary = (
            f"{experiment.t.size} samples at dt = {experiment.dt * 1e3:g} ms, "
            f"{len(experiment.layout.sensors)} channels, noise {config.noise.describe()}"
        )
        return Simulated(run, summary)

    def reference(self, run: int) -> dict[str, NDArray]:
        return self.task.reference(run)

    def problem(self, reference: dict[str, NDArray]) -> Problem:
        return self.task.problem(reference)

    def truth_cost(self, reference: dict[str, NDArray], problem: Problem) -> float:
        """The truth's cost on a simulated run's data from the clean channels the run's noise was added to (the
        configured car, which is the truth: the same numbers as simulating it again, without the simulation)."""
        t = self.task
        if isinstance(t, Task) and t.clean is not None and t.truth is not None and not t.corrections:
            return float(t.objective(reference).costs({f: t.clean[f][None] for f in t.families})[0])
        return super().truth_cost(reference, problem)

    def bound(self, at: NDArray | None = None) -> CramerRao:
        return self.task.bound(at)


def run_sigma(task: Task | JointTask) -> dict[str, NDArray]:
    """The noise sigma per family of each run, for the results file: `acc`, `disp` of run 1, `acc.run2`, ..."""
    if isinstance(task, Task):
        return task.sigma
    out = {}
    for i, t in enumerate(task.tasks, start=1):
        out.update({(f if i == 1 else f"{f}.run{i}"): s for f, s in t.sigma.items()})
    return out


def write_simulation_mdf(path: str | Path, run: SimulatedRun, comments: list[str]) -> None:
    """One simulated run as a data logger would record it (ASAM MDF4): the road inputs and every sensor's noisy
    channel, in SI units, on the simulation's grid."""
    exp = run.experiment
    channels = {name: (exp.t, exp.road[:, i]) for i, name in enumerate(ROAD)}
    units = dict.fromkeys(ROAD, "m")
    for family in exp.layout.families:
        for j, name in enumerate(exp.layout.names(family)):
            channels[name] = (exp.t, run.channels[family][:, j])
            units[name] = UNIT[family]
    write_record(path, channels, units=units, comment="\n".join(comments))


def write_simulation_h5(path: str | Path, run: SimulatedRun, seed: int) -> None:
    """One simulated run: the road, clean and noisy channels, coordinates, and the resolved config.

    Layout: /t, /road (n, 4); /clean/{acc, disp, q}; /noisy/{acc, disp} (each (n, k) with the channel names in its
    `columns` attribute); root attributes hold the resolved config (YAML), its SHA-256, the noise level, the seed
    and provenance.
    """
    import h5py  # start-up: h5py and the store (about 40 ms) only when a run is written as HDF5, not for diagnose

    from ...core.store import h5_file

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
        for group, channels in ((clean, run.clean_channels), (noisy, run.channels)):
            for family, values in channels.items():
                ds = group.create_dataset(family, data=values)
                ds.attrs["unit"] = UNIT[family]
                ds.attrs["columns"] = np.array(exp.layout.names(family), dtype=h5py.string_dtype())
        noisy.create_group("sigma")
        for family, sigma in run.sigma.items():
            noisy["sigma"].create_dataset(family, data=sigma).attrs["unit"] = UNIT[family]
        q = clean.create_dataset("q", data=run.clean.q)
        q.attrs["columns"] = np.array(DOF_NAMES, dtype=h5py.string_dtype())
        q.attrs["unit"] = "m (bounce, wheels), rad (roll, pitch)"
