"""An identification task: the experiment, the unknowns and their box, the reference data, the noise.

`build_task` turns a config (and optionally a measurement file) into a `Task`; `Task.reference(run)`
gives the data run `run` identifies from (clean responses plus that run's Eq. 15 noise, or the measured
responses); `Task.problem(reference)` gives the optimizer's `Problem`, whose costs come from one batched
simulation of the whole population.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .config import Config
from .crlb import CramerRao, cramer_rao
from .data import read_measurement
from .errors import InputError
from .experiment import Experiment, build_experiment, run_streams
from .models.effects import LIBRARY
from .noise import add_noise, estimate_noise_sigma, noise_sigma, sigma_from_level
from .objectives import Objective, objective_families
from .optimizers.base import Problem

MIN_SIGMA_FRACTION = 1e-3  # noise-free data: weight channels as if Np were 0.1 %, to keep wls finite


@dataclass(frozen=True)
class Task:
    """What is identified (names, box, truth) from which experiment, with which channels and noise."""

    config: Config
    experiment: Experiment
    names: tuple[str, ...]
    lower: NDArray
    upper: NDArray
    nominal: NDArray  # configured values of the unknowns
    truth: NDArray | None  # the true values when known
    families: tuple[str, ...]  # response families the objective uses
    clean: dict[str, NDArray] | None  # clean responses of the true car (simulated data)
    measured: dict[str, NDArray] | None  # responses from a measurement file
    sigma: dict[str, NDArray]  # noise standard deviation per channel, per family
    sigma_source: str  # how sigma was obtained
    data_file: str | None

    @property
    def dim(self) -> int:
        return len(self.names)

    @property
    def car_names(self) -> tuple[str, ...]:
        """The unknowns that are vehicle parameters (not ``effect.param``)."""
        return tuple(n for n in self.names if not is_effect_unknown(n))

    def with_unknowns(
        self,
        extra: tuple[str, ...] | list[str],
        limits: Mapping[str, tuple[float, float]] | None = None,
        start: Mapping[str, float] | None = None,
    ) -> Task:
        """The same task with more unknowns: effect parameters ``effect.param`` (e.g. ``hysteresis.alpha_f``)
        or further vehicle parameters (box: identify.bounds x configured value). Effect parameters' nominal
        values are the config's declared effect values or the library defaults (``start`` overrides), their box
        the effect's physical bounds (``limits`` narrows it).

        The augmented task's truth covers the vehicle unknowns only, so it is None here (effect parameters
        have no configured truth); callers compare ``car_names`` against the original task's truth.
        """
        names = list(self.names)
        lower, upper, nominal = list(self.lower), list(self.upper), list(self.nominal)
        for name in extra:
            if name in names:
                raise InputError(f"unknown '{name}' is listed twice", key="identify.unknowns")
            values = self.config.vehicle.values()
            if is_effect_unknown(name):
                lo, hi = effect_box(name)
                x0 = effect_nominal(self.config, name)
            elif name in values:  # a vehicle parameter: the configured bounds factors
                lo_f, hi_f = self.config.identify.bounds
                lo, hi, x0 = lo_f * values[name], hi_f * values[name], values[name]
            else:
                raise InputError(
                    f"'{name}' is neither a vehicle parameter nor an effect parameter (effect.param)",
                    key="identify.unknowns",
                )
            if limits and name in limits:
                lo, hi = max(lo, limits[name][0]), min(hi, limits[name][1])
            x0 = (start or {}).get(name, x0)
            names.append(name)
            lower.append(lo)
            upper.append(hi)
            nominal.append(float(np.clip(x0, lo, hi)))
        return dataclasses.replace(
            self,
            names=tuple(names),
            lower=np.array(lower, dtype=float),
            upper=np.array(upper, dtype=float),
            nominal=np.array(nominal, dtype=float),
            truth=None if len(names) > len(self.names) else self.truth,
        )

    def reference(self, run: int) -> dict[str, NDArray]:
        """The responses run `run` identifies from: measured ones, or clean plus the run's own noise."""
        if self.measured is not None:
            return self.measured
        assert self.clean is not None
        rng = run_streams(self.config.identify.seed, run).noise
        level = self.config.noise.level
        # Same draw order as `vehid simulate` (accelerations, then displacements): run 0 sees that file.
        noisy = {family: add_noise(self.clean[family], level, rng) for family in ("acc", "disp")}
        return {family: noisy[family] for family in self.families}

    def objective(self, reference: dict[str, NDArray]) -> Objective:
        return Objective(name=self.config.identify.objective, reference=reference, sigma=self.sigma)

    def problem(self, reference: dict[str, NDArray]) -> Problem:
        """The optimizer's view: batched costs (and weighted residuals) over the unknowns' box."""
        objective = self.objective(reference)
        names = self.names

        def simulate(X: NDArray):
            with np.errstate(all="ignore"):
                return self.experiment.simulate({n: X[:, j] for j, n in enumerate(names)})

        def cost(X: NDArray) -> NDArray:
            return objective.costs(simulate(X))

        def cost_and_residuals(X: NDArray) -> tuple[NDArray, NDArray]:
            return objective.costs_and_residuals(simulate(X))

        return Problem(self.lower, self.upper, cost, cost_and_residuals, names=names)

    @property
    def residual_samples(self) -> int:
        """R: how many weighted residuals the objective's channels give (4 channels per family)."""
        return int(self.experiment.t.size * 4 * len(self.families))

    @property
    def noise_free(self) -> bool:
        """Simulated data without noise: the bound is zero (the weights keep a floor only to stay finite)."""
        return self.measured is None and self.config.noise.level == 0

    def bound(self, at: NDArray | None = None) -> CramerRao:
        """The Cramér–Rao bound of this experiment at `at` (default: the truth, or the nominal car when unknown)."""
        if at is None:
            at = self.truth if self.truth is not None else self.nominal
        bound = cramer_rao(self.experiment, self.names, at, self.sigma)
        if self.noise_free:  # the bound scales with sigma, and sigma is zero
            bound = dataclasses.replace(bound, re_sd_percent=np.zeros_like(bound.re_sd_percent), nre_rms_percent=0.0)
        return bound


def is_effect_unknown(name: str) -> bool:
    """``effect.param`` names an effect parameter of the library (``hysteresis.alpha_f``)."""
    effect, dot, param = name.partition(".")
    return bool(dot) and effect in LIBRARY and param in LIBRARY[effect].names()


def effect_box(name: str) -> tuple[float, float]:
    """Physical bounds of an effect unknown ``effect.param`` (an open lower bound nudged just inside)."""
    effect, _, param = name.partition(".")
    if not is_effect_unknown(name):
        raise InputError(f"'{name}' is not an effect parameter (effect.param)", key="identify.unknowns")
    p = LIBRARY[effect].param(param)
    lo = p.lower + 1e-9 * (p.upper - p.lower) if p.open_lower else p.lower
    return float(lo), float(p.upper)


def effect_nominal(config: Config, name: str) -> float:
    """Configured value of an effect unknown: the declared effect's value, else the library default."""
    effect, _, param = name.partition(".")
    declared = config.vehicle.effect_values().get(effect)
    if declared is not None and param in declared:
        return float(declared[param])
    return float(LIBRARY[effect].defaults()[param])


def build_task(config: Config, data_file: str | Path | None = None) -> Task:
    """Sample the experiment, simulate the true car or read the measurement, fix the noise level."""
    ident = config.identify
    experiment = build_experiment(config, road_file=data_file)
    names = tuple(ident.unknowns)
    box = config.search_box()
    lower = np.array([box[n][0] for n in names])
    upper = np.array([box[n][1] for n in names])
    values = config.parameter_values()
    nominal = np.array([values[n] for n in names])
    families = objective_families(ident.objective, config.sensors)
    level = config.noise.level
    if data_file is None:
        truth = None if ident.truth == "none" else nominal
        response = experiment.simulate()
        clean = {"acc": response.acc, "disp": response.disp}
        floor = max(level, MIN_SIGMA_FRACTION)
        sigma = {f: noise_sigma(clean[f], floor) for f in families}
        source = f"Eq. 15 with Np = {level:g}" if level > 0 else f"noise-free data: weights of Np = {floor:g}"
        return Task(config, experiment, names, lower, upper, nominal, truth, families, clean, None, sigma, source, None)
    m = read_measurement(data_file)
    measured = {}
    for family in families:
        data = getattr(m, family)
        if data is None:
            need = f"{family}1..{family}4"
            raise InputError(
                f"objective '{ident.objective}' with sensors '{config.sensors}' needs columns {need}, "
                "which this file lacks",
                source=str(data_file),
            )
        measured[family] = data
    if level > 0:
        sigma = {f: sigma_from_level(measured[f], level) for f in families}
        source = f"Eq. 15 with Np = {level:g} (noise.level)"
    else:
        sigma = {f: estimate_noise_sigma(measured[f]) for f in families}
        source = "estimated from the data (third differences)"
    for family, s in sigma.items():
        if np.any(~(s > 0)):
            raise InputError(
                f"cannot estimate the noise of the {family} channels (are they constant?)", source=str(data_file)
            )
    truth = nominal if ident.truth == "config" else None
    return Task(
        config, experiment, names, lower, upper, nominal, truth, families, None, measured, sigma, source, str(data_file)
    )
