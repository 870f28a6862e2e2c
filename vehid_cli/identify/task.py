"""An identification task: the experiment, the unknowns and their box, the reference data, the noise.

`build_task` turns a config (and optionally a measurement file) into a `Task`; `Task.reference(run)`
gives the data run `run` identifies from (clean responses plus that run's Eq. 15 noise, or the measured
responses); `Task.problem(reference)` gives the optimizer's `Problem`, whose costs come from one batched
simulation of the whole population.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..config import Config
from ..core.errors import InputError
from ..core.streams import run_streams
from ..models.effects import LIBRARY
from ..models.faults import Channel, Context, Finding, fault_of
from ..optimizers import lsq
from ..optimizers.base import Problem
from .corrections import SensorCorrection, corrected, is_sensor_unknown, split_sensor
from .crlb import CramerRao, bound_from_information, cramer_rao, information, summed_information, weighted_sensitivities
from .experiment import Experiment, build_experiment, measurement_noise
from .forward import forward_gram
from .measured import experiment_of, read_run
from .objectives import Objective, mean_square, objective_families


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
    families: tuple[str, ...]  # channel families the objective uses
    clean: dict[str, NDArray] | None  # clean channels of the true car (simulated data), every family of the layout
    measured: dict[str, NDArray] | None  # channels from a measurement file
    sigma: dict[str, NDArray]  # noise standard deviation per channel, per family (the weights)
    sigma_source: str  # how sigma was obtained
    data_file: str | None
    observed: dict[str, NDArray] | None = None  # family -> (n, k) bool: each channel's own samples (None: all)
    offsets: bool = False  # one unknown offset per channel, profiled out (data.offsets: identify)
    drawn: dict[str, NDArray] | None = None  # simulated data: the noise sigma each run's noise is drawn with
    raw: dict[str, NDArray] | None = None  # measured data: the channels as read, before offsets were removed
    units: dict[str, tuple[str, str]] | None = None  # measured data: channel -> (its unit, where it came from)
    corrections: tuple[SensorCorrection, ...] = ()  # the measurement chain's corrections among the unknowns

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
            if is_sensor_unknown(name):
                lo, hi = (limits or {}).get(name, (-np.inf, np.inf))
                x0 = (start or {}).get(name, 0.0)
            elif is_effect_unknown(name):
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
        added = tuple(n for n in extra if is_sensor_unknown(n))
        return dataclasses.replace(
            self,
            names=tuple(names),
            lower=np.array(lower, dtype=float),
            upper=np.array(upper, dtype=float),
            nominal=np.array(nominal, dtype=float),
            truth=None if len(names) > len(self.names) else self.truth,
            corrections=self.corrections + tuple(self._correction(n, (start or {}).get(n, 0.0)) for n in added),
        )

    def channel_views(self, reference: dict[str, NDArray] | None = None) -> tuple[Channel, ...]:
        """Every measured channel beside the configured model's prediction of it, at its own samples (what the
        checks of the measurement chain read)."""
        reference = self.measured if reference is None else reference
        exp = self.experiment
        prediction = exp.outputs()
        raw = self.raw or {}
        units = {n: u for n, (u, origin) in (self.units or {}).items() if not origin.startswith("default")}
        free = self.offsets or self.config.data.offsets == "remove"
        kinds = {s.name: s.kind for s in exp.layout.sensors}
        out = []
        for family in self.families:
            for k, name in enumerate(exp.layout.names(family)):
                own = self._own(family, k)
                rows = slice(None) if own.all() else own  # sampled at every grid sample: views of t and raw, no copies
                y, p = reference[family][rows, k], prediction[family][rows, k]
                out.append(Channel(
                    name=name, family=family, column=k, kind=kinds.get(name, family), t=exp.t[rows], y=y - y.mean(),
                    pred=p - p.mean(), sigma=float(self.sigma[family][k]),
                    raw=(raw[family] if family in raw else reference[family])[rows, k], pred_mean=float(p.mean()),
                    unit=units.get(name, ""), offsets_free=free,
                ))  # fmt: skip
        return tuple(out)

    def _own(self, family: str, k: int) -> NDArray:
        """(n,) bool: the grid samples that are channel k of `family`'s own."""
        return np.ones(self.experiment.t.size, dtype=bool) if self.observed is None else self.observed[family][:, k]

    def _correction(self, name: str, start: float) -> SensorCorrection:
        """The correction behind the unknown ``sensor:<channel>:<param>`` (its context from this run's data)."""
        channel, param = split_sensor(name)
        where = {n: (f, k) for f in self.families for k, n in enumerate(self.experiment.layout.names(f))}
        if channel not in where or self.measured is None:
            raise InputError(f"'{name}' names no measured channel of the objective", key="identify.unknowns")
        family, k = where[channel]
        fault = fault_of(param)
        partner = where[param.partition(":")[2]][1] if fault.pair else None
        view = next(v for v in self.channel_views() if v.name == channel)
        finding = Finding(channel, fault.name, "warning", 0.0, "", fault=param, start={param: start})
        spec = fault.correction(view, finding)
        own = self._own(family, k)
        mask = None
        if spec.mask is not None:
            mask = np.zeros(own.size)
            mask[np.flatnonzero(own)[spec.mask]] = 1.0
        measured = self.measured[family][:, k]
        if self.offsets:  # the data's offset, which the fit profiles out, taken off what the model is given
            measured = measured - float(np.mean(measured[own])) + view.pred_mean
        ctx = Context(self.experiment.t, measured, mask)
        return SensorCorrection((name,), fault, family, k, partner, ctx)

    def reference(self, run: int) -> dict[str, NDArray]:
        """The responses run `run` identifies from: measured ones, or clean plus the run's own noise."""
        if self.measured is not None:
            return self.measured
        assert self.clean is not None
        assert self.drawn is not None
        rng = run_streams(self.config.identify.seed, run).noise
        # Same draw order as `vehid simulate` (accelerations, then displacements): run 0 sees that file.
        noisy = measurement_noise(self.clean, self.drawn, rng)
        return {family: noisy[family] for family in self.families}

    def objective(self, reference: dict[str, NDArray]) -> Objective:
        return Objective(
            name=self.config.identify.objective, reference=reference, sigma=self.sigma, observed=self.observed,
            offsets=self.offsets,
        )  # fmt: skip

    def problem(self, reference: dict[str, NDArray]) -> Problem:
        """The optimizer's view: batched costs (and weighted residuals) over the unknowns' box."""
        objective = self.objective(reference)
        names = self.names
        blockwise = all(c.fault.local for c in self.corrections)  # each block corrected alone (identify/forward.py)

        def simulate(X: NDArray) -> dict[str, NDArray]:
            return self.outputs({n: X[:, j] for j, n in enumerate(names)})

        def cost(X: NDArray) -> NDArray:
            return objective.costs(simulate(X))

        def cost_and_residuals(X: NDArray) -> tuple[NDArray, NDArray]:
            return chunked_residuals(objective, simulate, X, self.experiment.cars_per_chunk)

        def kept(X: NDArray, entries: NDArray) -> NDArray:
            return kept_residuals(objective, simulate, X, self.experiment.cars_per_chunk, entries)

        def gram(X: NDArray, scale: NDArray, entries: NDArray | None = None) -> NDArray | None:
            values = {n: X[:, j] for j, n in enumerate(names)}
            car = {n: v for n, v in values.items() if not is_sensor_unknown(n)}
            if not self.experiment.long or not self.experiment.blocked(car) or not blockwise:
                return None  # a short record's Jacobian is held (today's path); a delay or drift reads other samples
            with np.errstate(all="ignore"):
                return forward_gram(self.experiment, objective, values, scale, entries, self.corrections)

        def linearised(x: NDArray) -> tuple[float, NDArray, NDArray] | None:
            with np.errstate(all="ignore"):
                got = self.experiment.exact_sensitivities(names, x)
                if got is None:
                    return None
                costs, residuals = objective.costs_and_residuals({f: v[None] for f, v in got[0].items()}, True)
                return float(costs[0]), residuals[0], objective.residual_jacobian(got[1])

        def normal(x: NDArray, entries: NDArray | None = None) -> tuple[float, NDArray, NDArray, NDArray] | None:
            sums = objective.normal_sums(len(names), entries)
            if sums is None:
                return None
            with np.errstate(all="ignore"):
                got = self.experiment.exact_sensitivities(names, x, sink=sums)
                if got is None:
                    return None
                costs, residuals = objective.costs_and_residuals({f: v[None] for f, v in got[0].items()}, True)
                return float(costs[0]), residuals[0], *sums.result()

        exact = not self.corrections and self.experiment.exact_applies(names)
        long = objective.size * len(names) * 8 > lsq.LONG_JACOBIAN_BYTES  # its Jacobian: summed, never made
        return Problem(
            self.lower, self.upper, cost, cost_and_residuals, names=names,
            linearised=linearised if exact and not long else None, normal=normal if exact and long else None,
            kept=kept, gram=gram,
        )  # fmt: skip

    def outputs(self, values: Mapping[str, NDArray]) -> dict[str, NDArray]:
        """The model's channels (family -> (P, n, k)) for a batch of the unknowns' values, as the measurement chain
        records them (the corrections among the unknowns applied)."""
        car = {n: v for n, v in values.items() if not is_sensor_unknown(n)}
        with np.errstate(all="ignore"):
            out = self.experiment.outputs(car)
            return corrected(self.corrections, out, values) if self.corrections else out

    @property
    def channel_names(self) -> tuple[str, ...]:
        """The objective's channels (its families' layout names, family by family)."""
        return tuple(n for f in self.families for n in self.experiment.layout.names(f))

    def residual_channels(self, reference: dict[str, NDArray]) -> NDArray:
        """(R,) the index into `channel_names` of each weighted residual entry."""
        return self.objective(reference).entry_channels()

    @property
    def residual_samples(self) -> int:
        """R: how many weighted residuals the objective's channels give (each channel's observed samples)."""
        if self.observed is not None:
            return int(sum(np.count_nonzero(self.observed[f]) for f in self.families))
        return int(self.experiment.t.size * sum(self.sigma[f].size for f in self.families))

    @property
    def noise_free(self) -> bool:
        """Simulated data without noise: the bound is zero (the weights keep a floor only to stay finite)."""
        return self.drawn is not None and not any(np.any(s > 0) for s in self.drawn.values())

    def information(self, at: NDArray) -> NDArray:
        """Fisher information (D, D) of the relative unknowns at `at` (crlb.information; a long record's a parameter
        at a time, `information_by_parameter`, unless exact sensitivities apply: they never hold the perturbed cars)."""
        at = np.asarray(at, dtype=float)
        long = 2 * at.size * self.residual_samples * 8 > LONG_INFORMATION_BYTES
        if long and not self.experiment.exact_applies(self.names):  # exact sensitivities hold no perturbed cars
            return information_by_parameter(self.experiment, self.names, at, self.sigma, self.observed, self.offsets)
        if long:  # ... and are summed block by block, never held
            F = summed_information(self.experiment, self.names, at, self.sigma, self.observed, self.offsets)
            if F is not None:
                return F
        return information(self.experiment, self.names, at, self.sigma, self.observed, self.offsets)

    def bound(self, at: NDArray | None = None) -> CramerRao:
        """The Cramér–Rao bound of this experiment at `at` (default: the truth, or the nominal car when unknown)."""
        if at is None:
            at = self.truth if self.truth is not None else self.nominal
        if 2 * np.size(at) * self.residual_samples * 8 > LONG_INFORMATION_BYTES:
            bound = bound_from_information(self.names, at, self.information(at))
        else:
            bound = cramer_rao(
                self.experiment, self.names, at, self.sigma, observed=self.observed, offsets=self.offsets
            )
        if self.noise_free:  # the bound scales with sigma, and sigma is zero
            bound = dataclasses.replace(bound, re_sd_percent=np.zeros_like(bound.re_sd_percent), nre_rms_percent=0.0)
        return bound


LONG_INFORMATION_BYTES = 32 * 2**20  # sensitivities of all 2D perturbed cars above this: one parameter at a time


class _Holding:
    """An experiment with some unknowns held at given values: `outputs` of the others, a car at a time."""

    def __init__(self, experiment: Experiment, held: Mapping[str, float]):
        self.experiment = experiment
        self.held = dict(held)

    def outputs(self, values: Mapping[str, NDArray]) -> dict[str, NDArray]:
        cars = [
            self.experiment.outputs({**self.held, **{n: v[i : i + 1] for n, v in values.items()}})
            for i in range(len(next(iter(values.values()))))
        ]
        return {f: np.concatenate([c[f] for c in cars]) for f in cars[0]}


def information_by_parameter(
    experiment: Experiment,
    names: tuple[str, ...],
    at: NDArray,
    sigma: Mapping[str, NDArray],
    observed: Mapping[str, NDArray] | None,
    offsets: bool,
) -> NDArray:
    """Fisher information (D, D) as crlb.information, to round-off, holding a long record's sensitivities for one
    parameter at a time (its two perturbed cars, simulated one by one) and the weighted sensitivities (D, R) once,
    never the 2D perturbed cars' channels together (a 60 s record at 1 kHz: 140 MB of them, 270 MB at the peak)."""
    rows = None
    for j, name in enumerate(names):
        held = {n: float(v) for i, (n, v) in enumerate(zip(names, at, strict=True)) if i != j}
        W = weighted_sensitivities(_Holding(experiment, held), (name,), at[j : j + 1], sigma, observed, offsets)
        parts = []
        for family, w in W.items():
            flat = w[..., 0].reshape(-1)
            parts.append(flat if observed is None else flat[np.flatnonzero(observed[family])])
        if rows is None:
            rows = np.empty((len(names), sum(p.size for p in parts)))
        np.concatenate(parts, out=rows[j])
    assert rows is not None
    return rows @ rows.T


def chunked_residuals(
    objective: Objective,
    simulate: Callable[[NDArray], dict[str, NDArray]],
    X: NDArray,
    chunk: int,
) -> tuple[NDArray, NDArray]:
    """Costs (P,) and weighted residuals (P, R) of `objective` for the candidates X (P, D), simulated `chunk` cars at
    a time into one array: a long record's channels (and the error beside them) are held for one chunk of cars only,
    never for the whole batch (a Jacobian's nine cars at 60 s and 1 kHz: 70 MB of channels, as much again of
    errors); each chunk's residuals are written straight into their rows, and its channels let go before its costs
    are squared (a chunk of two cars of a 60 s record: 8 MB per copy). Each car's numbers are the same either way:
    no chunk holds a single car, whose cost NumPy sums in another order than a row of a batch's."""
    P = len(X)
    if P <= max(2, chunk):
        return objective.costs_and_residuals(simulate(X))
    costs = np.empty(P)
    residuals = np.empty((P, objective.size))
    for start, stop in _chunks(P, chunk):
        outputs = simulate(X[start:stop])
        rows = objective.residuals(outputs, out=residuals[start:stop])
        if objective.name == "wls":
            del outputs  # the chunk's channels, before the square of its residuals
            costs[start:stop] = mean_square(rows)
        else:
            costs[start:stop] = objective.costs(outputs)
    return costs, residuals


def kept_residuals(
    objective: Objective, simulate: Callable[[NDArray], dict[str, NDArray]], X: NDArray, chunk: int, entries: NDArray
) -> NDArray:
    """The weighted residuals (P, entries.size) of the candidates X (P, D) at the `entries` only (increasing indices
    into the objective's R), simulated in chunks as `chunked_residuals`: a long record's batch of held-in entries
    without the (P, R) array (a forward-difference Jacobian's ten cars at 60 s: 38 MB, 29 of them kept). The same
    numbers as the whole vectors' entries."""
    out = np.empty((len(X), entries.size))
    for start, stop in _chunks(len(X), chunk):
        objective.residuals(simulate(X[start:stop]), out=out[start:stop], entries=entries)
    return out


def _chunks(P: int, chunk: int) -> list[tuple[int, int]]:
    """(start, stop) of the chunks of `chunk` cars (at least 2) a batch of P is simulated in; a last lone car joins the
    chunk before it (a chunk of one car sums its cost in another order than a row of a batch)."""
    starts = list(range(0, P, max(2, chunk)))
    if len(starts) > 1 and P - starts[-1] == 1:
        starts.pop()
    return list(zip(starts, [*starts[1:], P], strict=True))


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
    """Sample the experiment, simulate the true car or read the measured run, fix the noise of each channel."""
    ident = config.identify
    names = tuple(ident.unknowns)
    box = config.search_box()
    lower = np.array([box[n][0] for n in names])
    upper = np.array([box[n][1] for n in names])
    values = config.parameter_values()
    nominal = np.array([values[n] for n in names])
    layout = config.sensor_layout()
    families = objective_families(ident.objective, config.sensors, layout.families)
    offsets = config.data.offsets == "identify"
    if data_file is None:
        experiment = build_experiment(config)
        truth = None if ident.truth == "none" else nominal
        clean = experiment.outputs()
        noise = experiment.noise
        drawn = {f: noise.drawn(f, clean[f]) for f in clean}
        sigma = {f: noise.weights(f, clean[f]) for f in families}
        source = noise.describe_simulated(families)
        return Task(
            config, experiment, names, lower, upper, nominal, truth, families, clean, None, sigma, source, None,
            offsets=offsets, drawn=drawn,
        )  # fmt: skip
    run = read_run(config, data_file, families)
    experiment = experiment_of(config, run)
    noise = experiment.noise
    sigma = {}
    for family in families:
        mask = None if run.observed is None else run.observed[family]
        sigma[family] = noise.estimated(family, run.outputs[family], mask)
    source = noise.describe_measured(families)
    for family, s in sigma.items():
        if np.any(~(s > 0)):
            bad = [n for n, v in zip(experiment.layout.names(family), s, strict=True) if not v > 0]
            raise InputError(
                f"cannot estimate the noise of the {family} channel(s) {', '.join(bad)} (are they constant?)",
                source=str(data_file),
            )
    truth = nominal if ident.truth == "config" else None
    return Task(
        config, experiment, names, lower, upper, nominal, truth, families, None, run.outputs, sigma, source,
        str(data_file), observed=run.observed, offsets=offsets, raw=run.raw, units=run.units,
    )  # fmt: skip


@dataclass(frozen=True)
class JointTask:
    """Several runs of one car identified together: one parameter set, each run its own road, noise and offsets.

    The costs combine as one objective over all runs (the sum of the runs' numerators over the sum of their
    denominators: for wls the mean squared weighted residual over every sample of every run), the residuals are
    concatenated, and the Fisher information is the sum of the runs' (independent noise)."""

    tasks: tuple[Task, ...]

    def __post_init__(self) -> None:
        if len(self.tasks) < 2:
            raise ValueError("a joint task needs at least two runs")

    @property
    def config(self) -> Config:
        return self.tasks[0].config

    @property
    def names(self) -> tuple[str, ...]:
        return self.tasks[0].names

    @property
    def lower(self) -> NDArray:
        return self.tasks[0].lower

    @property
    def upper(self) -> NDArray:
        return self.tasks[0].upper

    @property
    def nominal(self) -> NDArray:
        return self.tasks[0].nominal

    @property
    def truth(self) -> NDArray | None:
        return self.tasks[0].truth

    @property
    def families(self) -> tuple[str, ...]:
        return self.tasks[0].families

    def with_unknowns(
        self,
        extra: tuple[str, ...] | list[str],
        limits: Mapping[str, tuple[float, float]] | None = None,
        start: Mapping[str, float] | None = None,
    ) -> JointTask:
        """Every run with the same further unknowns (Task.with_unknowns)."""
        return JointTask(tuple(t.with_unknowns(extra, limits=limits, start=start) for t in self.tasks))

    @property
    def data_files(self) -> tuple[str, ...]:
        return tuple(t.data_file for t in self.tasks if t.data_file is not None)

    @property
    def sigma_source(self) -> str:
        sources = dict.fromkeys(t.sigma_source for t in self.tasks)
        return "; ".join(sources)

    @property
    def residual_samples(self) -> int:
        return sum(t.residual_samples for t in self.tasks)

    @property
    def channel_names(self) -> tuple[str, ...]:
        return self.tasks[0].channel_names

    def residual_channels(self, references: tuple[dict[str, NDArray], ...]) -> NDArray:
        return np.concatenate([t.residual_channels(r) for t, r in zip(self.tasks, references, strict=True)])

    def reference(self, run: int) -> tuple[dict[str, NDArray], ...]:
        return tuple(t.reference(run) for t in self.tasks)

    def problem(self, references: tuple[dict[str, NDArray], ...]) -> Problem:
        """One problem over every run: each candidate simulated on each run's road."""
        objectives = [t.objective(r) for t, r in zip(self.tasks, references, strict=True)]
        names = self.names

        def outputs(X: NDArray) -> list[dict[str, NDArray]]:
            values = {n: X[:, j] for j, n in enumerate(names)}
            with np.errstate(all="ignore"):
                return [t.experiment.outputs(values) for t in self.tasks]

        def combined(ys: list[dict[str, NDArray]]) -> NDArray:
            parts = [o.parts(y) for o, y in zip(objectives, ys, strict=True)]
            return sum(p[0] for p in parts) / sum(p[1] for p in parts)

        def cost(X: NDArray) -> NDArray:
            return combined(outputs(X))

        def cost_and_residuals(X: NDArray) -> tuple[NDArray, NDArray]:
            ys = outputs(X)
            residuals = np.concatenate([o.residuals(y) for o, y in zip(objectives, ys, strict=True)], axis=-1)
            return combined(ys), residuals

        return Problem(self.lower, self.upper, cost, cost_and_residuals, names=names)

    def bound(self, at: NDArray | None = None) -> CramerRao:
        """The bound of all runs together: the sum of their Fisher information."""
        if at is None:
            at = self.truth if self.truth is not None else self.nominal
        F = sum(t.information(at) for t in self.tasks)
        return bound_from_information(self.names, at, F)


def build_tasks(config: Config, data_files: tuple[str | Path, ...] = ()) -> Task | JointTask:
    """The task of the simulated run (no files), of one measured run, or of several measured runs together."""
    if len(data_files) <= 1:
        return build_task(config, data_files[0] if data_files else None)
    return JointTask(tuple(build_task(config, f) for f in data_files))
