"""The seam between a system under test and the campaign machinery: what the car and the damper bench offer.

A `System` is built once per campaign (from a config and, optionally, measured data) and shipped to the
workers; run r of a campaign is `system.identify_run(r)`, a function of the config, the seed and r only, so
results are bit-identical whatever the executor. After the runs, `conclude(records)` gives what the system
adds to the campaign (the damper's identified model, held-out J, real-time check and traces).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from numpy.typing import NDArray

from ..config import AnyConfig
from ..core.errors import InputError
from ..core.progress import ProgressHook
from ..core.streams import run_streams
from ..diagnose.checks import Checks
from ..identify.crlb import CramerRao
from ..identify.records import Campaign, RunRecord
from ..identify.source import DataSource
from ..optimizers import get_optimizer
from ..optimizers.base import Problem

Log = Callable[[str], None]


@dataclass(frozen=True)
class Simulated:
    """What `vehid simulate` made: the simulated run (for its figure) and a one-line summary of the file."""

    run: Any  # experiment.SimulatedRun (the car) or systems.damper.SimulatedBench (the damper)
    summary: str
    title: str = ""  # of its figure


@dataclass(frozen=True)
class Box:
    """The unknowns and their search box: names, lower and upper bounds, configured values, the truth."""

    names: tuple[str, ...]
    lower: NDArray
    upper: NDArray
    nominal: NDArray  # configured values of the unknowns
    truth: NDArray | None  # the true values when known


class System(ABC):
    """What a system under test offers the machine above it: campaigns (the box, the reference data of run r, the
    problem, the bound, what it concludes), `vehid simulate`, `vehid diagnose`, and the tables and figures of its
    campaigns. Subclasses set `name` and implement the hooks; `systems.register_system` makes a system known.
    Nothing outside `systems/` (and the config registry) asks which system it holds: it calls these hooks."""

    name: ClassVar[str]  # the config's `system` key and the results file's `system` attribute
    objective: ClassVar[str]  # what `cost` means in the records (f1, f2, wls; J)
    findings_type: ClassVar[Any] = None  # what `conclude` returns: a class with write_h5(group), read_h5(group)
    simulation_suffixes: ClassVar[tuple[str, ...]] = (".csv", ".h5", ".hdf5")  # what `write_simulation` writes
    designable: ClassVar[bool] = False  # `vehid design` can plan its test
    # config keys that are the method, not the experiment: campaigns differing only there share a report
    method_keys: ClassVar[tuple[str, ...]] = (
        "identify.algorithm", "identify.objective", "identify.runs", "identify.seed", "identify.budget",
        "identify.start", "sensors", "noise.level",
    )  # fmt: skip
    diagnosis_defaults: ClassVar[tuple[str, ...]] = ()  # --set lines a diagnosis starts from (the user's come after)

    config: AnyConfig
    source: DataSource  # the measured runs (and related files), resolved once
    box: Box
    sigma: dict[str, NDArray]  # noise standard deviation per channel, per family
    sigma_source: str  # how sigma was obtained

    @property
    def names(self) -> tuple[str, ...]:
        return self.box.names

    @property
    def data_file(self) -> str | None:
        """How results name the measured run(s) (None: simulated data)."""
        return self.source.label

    @property
    def runs(self) -> int:
        """Runs of the campaign: identify.runs on simulated data (each its own noise); one fit on measured data,
        where every run would identify from the same data."""
        return self.config.identify.runs if self.source.simulated else 1

    @property
    def residual_samples(self) -> int:
        """R: how many weighted residuals the objective gives (behind chi²)."""
        return 0

    @property
    def channel_names(self) -> tuple[str, ...]:
        """The measured channels the fit compares (per-channel chi² and checks name them)."""
        return ("all",)

    def residual_channels(self, reference: Any) -> NDArray:
        """(R,) the index into `channel_names` of each weighted residual entry of `problem(reference)`."""
        return np.zeros(0, dtype=int)

    def checks(self) -> Checks | None:
        """The pre-fit checks of the measured data against the configured model (None: simulated data, or a system
        without checks)."""
        return None

    def data_files(self) -> tuple[str, ...]:
        """Every file the campaign's results depend on (their bytes enter the campaign key)."""
        return self.source.files

    # ---------------------------------------------------------------------------- what differs per system, by class

    @classmethod
    def objective_label(cls, config: AnyConfig) -> str:
        """What a campaign's cost is for this config (results files, tables, progress)."""
        return cls.objective

    @classmethod
    def results_attributes(cls, config: AnyConfig) -> dict[str, str]:
        """Root attributes of a campaign file that only this system has (the car's sensors, the damper's model)."""
        return {}

    @classmethod
    def design_variables(cls, config: AnyConfig) -> tuple | None:
        """The variables of the test `vehid design` plans through the config (`config.design.DesignVariable`s, each
        written to its key), or None: the system plans its test as a `design.Plan` (the car)."""
        return None

    @classmethod
    def diagnose(
        cls, config: AnyConfig, data: tuple[str, ...], validate: tuple[str, ...], log: Log | None,
        progress: ProgressHook | None = None,
    ) -> Any:  # fmt: skip
        """`vehid diagnose`: close the loop on the measured `data` (judged on the `validate` runs) -> a
        `diagnose.result.Diagnosis`; `progress` hears of its steps."""
        raise InputError(f"vehid diagnose has no loop for a {cls.name} yet", source=config.source, key="system")

    @classmethod
    def tables(cls, campaigns: Sequence[Campaign], files: Sequence[str]) -> list:
        """The terminal (rich) tables of campaigns of this system: by default, each campaign's parameters."""
        from .report import parameter_tables

        return parameter_tables(campaigns, files)

    @classmethod
    def render(cls, campaigns: Sequence[Campaign], files: Sequence[str], fmt: str, published: dict | None) -> str:
        """A report in `fmt` (md, csv, latex; JSON is the same for every system) of campaigns of this system."""
        from .report import render_parameters

        return render_parameters(campaigns, files, fmt)

    @classmethod
    def figures(cls, campaigns: Sequence[Campaign], files: Sequence[str], out_dir: Path) -> list[Path]:
        """`vehid report --plots`: the figures of campaigns of this system; the paths written."""
        return []

    @classmethod
    def plot_simulation(cls, simulated: Simulated, path: Path) -> None:
        """`vehid simulate --plot`: the figure of one simulated run."""
        raise InputError(f"no figure of a simulated {cls.name} run yet", source=str(path))

    @classmethod
    @abstractmethod
    def write_simulation(
        cls, config: AnyConfig, target: Path, seed: int, road: Path | None = None, origin: str = ""
    ) -> Simulated:
        """Simulate the configured system with run 0's noise stream of `seed` and write it to `target` (.csv, or
        .h5 with clean and noisy data); `origin` (the command) goes into the file's comments."""

    @abstractmethod
    def reference(self, run: int) -> Any:
        """The data run `run` identifies from: measured, or simulated with the run's own noise."""

    @abstractmethod
    def problem(self, reference: Any) -> Problem:
        """The optimizer's view of one run: batched costs (and residuals) over the unknowns' box."""

    def bound(self, at: NDArray | None = None) -> CramerRao:
        """The Cramér–Rao bound at `at` (default: the truth, or the configured values); NaN where the system has
        none."""
        D = len(self.names)
        if at is None:
            at = self.box.truth if self.box.truth is not None else self.box.nominal
        return CramerRao(
            names=self.names, values=at, fisher=np.full((D, D), np.nan), re_sd_percent=np.full(D, np.nan),
            nre_rms_percent=float("nan"), identifiable=np.ones(D, dtype=bool), condition=float("nan"),
        )  # fmt: skip

    def unidentifiable(self, bound: CramerRao) -> str | None:
        """Why the data cannot separate the unknowns (the free combination and what would fix it), or None: a campaign
        stops on it unless forced."""
        return None

    def start(self, rng: np.random.Generator) -> NDArray | None:
        """Where a run's optimizer starts: the configured values (`config`, or `auto` on measured data), else None
        (the optimizer's own random start from the run's stream)."""
        mode = self.config.identify.start
        return self.box.nominal if mode == "config" or (mode == "auto" and not self.source.simulated) else None

    def identify_run(self, index: int) -> RunRecord:
        """Run `index`: its own data (noise) and its own optimizer stream, within the evaluation budget."""
        ident = self.config.identify
        streams = run_streams(ident.seed, index)
        reference = self.reference(index)
        problem = self.problem(reference)
        # Diagnostic, not charged to the budget: the truth's cost on this run's data tells a converged run.
        truth_cost = self.truth_cost(reference, problem)
        algorithm = ident.algorithm
        optimizer = get_optimizer(algorithm.name, algorithm.population, algorithm.iterations)
        x0 = self.start(streams.optimizer)
        # Parameter sets that make the model blow up overflow on their way to a NaN/Inf cost: the optimizer gives
        # them the finite penalty and counts them (`penalised`), so NumPy's floating-point warnings are noise.
        with np.errstate(over="ignore", invalid="ignore", divide="ignore", under="ignore"):
            result = optimizer.minimize(problem, streams.optimizer, budget=ident.budget, x0=x0)
            # Diagnostic, not charged: residual power over noise power at the estimate tells whether the model fits
            # (the residuals the search kept at its estimate, else one more simulation).
            if result.residuals is not None:
                residuals = result.residuals[None, :]
            else:
                _, residuals = problem.residuals(result.x[None, :])
            chi2 = float(np.mean(residuals**2))
        return RunRecord(
            index=index, estimate=result.x, cost=result.cost, evaluations=result.evaluations,
            penalised=result.penalised, wall_s=result.wall_s, history_evals=result.history_evals,
            history_cost=result.history_cost, truth_cost=truth_cost, chi2=chi2,
            channel_chi2=self._channel_chi2(reference, residuals[0]),
        )  # fmt: skip

    def truth_cost(self, reference: Any, problem: Problem) -> float:
        """The truth's cost on a run's data (`problem`'s cost at the truth; NaN without a truth): one simulation of
        the truth. A system that holds the clean data its runs were drawn from gives it without one."""
        truth = self.box.truth
        return float(problem.cost(truth[None, :])[0]) if truth is not None else float("nan")

    def _channel_chi2(self, reference: Any, residuals: NDArray) -> NDArray:
        """Each channel's mean squared weighted residual (C,), in `channel_names` order (NaN: no entries)."""
        which = self.residual_channels(reference)
        C = len(self.channel_names)
        if which.size != residuals.size:  # a system that does not tell: the whole residual as one channel
            return np.array([float(np.mean(residuals**2))] * C) if C == 1 else np.full(C, np.nan)
        with np.errstate(all="ignore"):  # an unstable candidate's residuals overflow: its chi2 is inf, said elsewhere
            sums = np.bincount(which, weights=residuals**2, minlength=C)
            counts = np.bincount(which, minlength=C)
            return sums / counts

    def conclude(self, records: tuple[RunRecord, ...]) -> Any:
        """What the system adds to the finished campaign (None: nothing beyond the records)."""
        return None
