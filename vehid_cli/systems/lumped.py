"""The seam's base for linear lumped-parameter rigs (the quarter car, the half car): a rig is its matrices
M, C, K and input matrices B0 (inputs through springs, forces) and B1 (inputs through dampers: the road's velocity),
its sensor rows and its configured inputs; everything else, the machine above gets here.

A rig's sub-package subclasses `LumpedSystem` with `matrices(p)` (a batch of parameter sets -> M, C, K, B0, B1),
`sensor_rows(p)` (the layout's displacement and acceleration rows over the coordinates), `configured_inputs(t)`
and `remedies(free)` (what would make a free combination of unknowns identifiable). Simulation is the exact
first-order hold of `sim.lumped` (the compiled modal recursions of the full car), the objective weighted least
squares of every channel, several measured runs are identified jointly (one parameter set, the information
summed), and unknowns the data cannot separate stop the campaign with the free combination named
(`unidentifiable`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
from numpy.typing import NDArray

from .. import __version__
from ..config.lumped import LumpedConfig
from ..core.errors import InputError
from ..core.streams import experiment_rng, run_streams
from ..identify.crlb import CramerRao, bound_from_information
from ..identify.experiment import measurement_noise
from ..identify.objectives import Objective
from ..identify.source import DataFiles, DataSource
from ..io.measurement import time_grid, write_csv
from ..io.read import read_record
from ..models.noise import NoiseModel
from ..models.road import RandomProfile, bump_unit, chirp
from ..optimizers.base import Problem
from ..sim.lumped import lumped_outputs
from ..sim.sensitivity import central_points, lumped_sensitivities, stencil
from .base import Box, Simulated, System

FAMILIES = ("acc", "disp")  # channel order: accelerations, then displacements (noise draws, residuals)
MIN_SAMPLES_PER_PERIOD = 10  # of the fastest undamped mode
NULL_RATIO = 1e-9  # eigenvalue of the correlation-scaled information, relative to the largest, that is a free direction


@dataclass(frozen=True)
class RigRun:
    """One run of a rig: its time grid, inputs and (measured) channels."""

    t: NDArray  # (n,) [s], uniform
    u: NDArray  # (n, nu) inputs in `input_names` order [m, N]
    measured: dict[str, NDArray] | None  # family -> (n, k); None: simulated
    source: str

    @property
    def dt(self) -> float:
        return float((self.t[-1] - self.t[0]) / (self.t.size - 1))


class LumpedSystem(System):
    """A linear rig: run r identifies from its clean channels plus run r's noise, or from the measured runs."""

    objective: ClassVar[str] = "wls"
    simulation_suffixes: ClassVar[tuple[str, ...]] = (".csv",)
    diagnosis_defaults: ClassVar[tuple[str, ...]] = ("noise.level=0",)  # the noise estimated from the data
    groups: ClassVar[tuple[tuple[str, tuple[str, ...]], ...]] = ()  # known parameters a diagnosis may free, grouped
    axles: ClassVar[tuple[str, ...]] = ("f", "r")  # the car's axles the rig's struts stand for (effects' _f, _r)
    companion_names: ClassVar[dict[str, str]] = {}  # the car's parameter names -> the rig's (an effect's companions)
    excluded_effects: ClassVar[tuple[str, ...]] = ()  # library effects the rig's linear model already has
    designable: ClassVar[bool] = True  # through the config's design variables (`design_variables`)
    kernel: bool = False  # simulate by RK4 on the compiled kernel even without effects (a diagnosis: one scheme)
    config: LumpedConfig

    # ------------------------------------------------------------------ what a rig defines
    def matrices(self, p: dict[str, NDArray]) -> tuple[NDArray, NDArray, NDArray, NDArray, NDArray]:
        """M, C, K (P, d, d), B0, B1 (P, d, nu) of a batch of parameter sets (p: name -> (P,))."""
        raise NotImplementedError

    def sensor_rows(self, p: dict[str, NDArray]) -> tuple[NDArray, NDArray]:
        """Sq (P, kd, d), Sa (P, ka, d): the layout's displacement and acceleration channels over q and qdd."""
        raise NotImplementedError

    @classmethod
    def configured_inputs(cls, config: LumpedConfig, t: NDArray) -> NDArray:
        """(n, nu) the configured inputs of `config` on the grid t, in `config.input_names` order."""
        raise NotImplementedError

    def struts(self, p: dict[str, NDArray]) -> tuple[NDArray, NDArray, NDArray, NDArray | None]:
        """The rig's struts in the car's corner slots: suspension rows D (P, 4, d), tyre rows T (P, 4, d) and their
        road inputs ET (4, nu) (tyre deflection T q + ET u), and the linear model's tyre damping (P, 4) or None."""
        raise NotImplementedError

    def strut_damping(self, p: dict[str, NDArray]) -> NDArray:
        """(P, 2) the linear damping of the front and rear struts [N s/m]."""
        raise NotImplementedError

    def remedies(self, free: tuple[str, ...]) -> str:
        """What would make the free unknowns identifiable, in words."""
        return "fix one of them (remove it from identify.unknowns), or add an input or a sensor that sees it"

    @classmethod
    def design_variables(cls, config: LumpedConfig) -> tuple:
        """The chirp's band and amplitude, the force's amplitude, the bump's speed and height (config `design:`)."""
        return config.design_variables()

    # ------------------------------------------------------------------ construction
    def __init__(self, config: LumpedConfig, source: DataFiles | DataSource = None):
        self.config = config
        self.source = DataSource.resolve(config, source)
        names = tuple(config.identify.unknowns)
        values = config.parameter_values()
        box = config.search_box()
        nominal = np.array([values[n] for n in names])
        truth_known = config.identify.truth == "config" or (config.identify.truth == "auto" and self.source.simulated)
        self.box = Box(names, np.array([box[n][0] for n in names]), np.array([box[n][1] for n in names]),
                       nominal, nominal.copy() if truth_known else None)  # fmt: skip
        self.families = tuple(f for f in FAMILIES if any(s.family == f for s in config.layout))
        floors = {}
        for f in self.families:
            family = getattr(config.noise.sigma, f)
            own = [s.sigma or family for s in config.layout if s.family == f]
            floors[f] = np.array([np.nan if v is None else v for v in own], dtype=float)
        self.noise = NoiseModel(config.noise.level, floors)
        if self.source.simulated:
            grid = time_grid(config.simulation.duration, config.simulation.dt)
            self.rigs = (RigRun(grid, self.configured_inputs(config, grid), None, "config"),)
        else:
            self.rigs = tuple(read_rig_run(config, f, self.families, self.configured_inputs) for f in self.source.runs)
        for rig in self.rigs:
            self.check_time_step(rig.dt, "simulation.dt" if rig.measured is None else f"{rig.source}: time step")
        self._prepare_noise()
        self._checks = None

    def checks(self):
        """Every measured channel of every run against the configured rig (`systems.lumped_checks`), once; None on
        simulated data."""
        if self.source.simulated:
            return None
        if self._checks is None:
            from .lumped_checks import rig_checks

            self._checks = rig_checks(self)
        return self._checks

    def _prepare_noise(self) -> None:
        if self.source.simulated:
            self.clean = self.outputs(self.box.nominal[None, :], 0)
            self.clean = {f: v[0] for f, v in self.clean.items()}
            self.drawn = {f: self.noise.drawn(f, self.clean[f]) for f in self.families}
            self.weights = ({f: self.noise.weights(f, self.clean[f]) for f in self.families},)
            self.sigma_source = self.noise.describe_simulated(self.families)
        else:
            self.weights = tuple({f: self.noise.estimated(f, r.measured[f]) for f in self.families} for r in self.rigs)
            for rig, w in zip(self.rigs, self.weights, strict=True):
                for f, s in w.items():
                    if np.any(~(s > 0)):
                        raise InputError(f"cannot estimate the noise of a {f} channel (is it constant?)",
                                         source=rig.source)  # fmt: skip
            self.sigma_source = self.noise.describe_measured(self.families)
        self.sigma = {(f if i == 0 else f"{f}.run{i + 1}"): s for i, w in enumerate(self.weights) for f, s in w.items()}

    def parameters(self, X: NDArray, names: tuple[str, ...] | None = None) -> dict[str, NDArray]:
        """Every parameter for a batch of values X (P, D) of `names` (default the unknowns); configured elsewhere."""
        P = X.shape[0]
        values = self.config.parameter_values()
        out = {n: np.full(P, float(v)) for n, v in values.items()}
        out.update({n: np.asarray(X[:, j], dtype=float) for j, n in enumerate(self.names if names is None else names)})
        return out

    def check_time_step(self, dt: float, key: str) -> None:
        """Refuse a time step too coarse for the configured rig's fastest mode."""
        M, _, K, _, _ = self.matrices(self.parameters(self.box.nominal[None, :]))
        w2 = np.linalg.eigvals(np.linalg.solve(M[0], K[0])).real
        f_max = float(np.sqrt(max(w2.max(), 0.0))) / (2 * np.pi)
        dt_max = 1.0 / (MIN_SAMPLES_PER_PERIOD * f_max)
        if dt > dt_max * (1 + 1e-9):
            raise InputError(f"time step {dt:g} s is too coarse for the fastest mode at {f_max:.3g} Hz: use dt <= "
                             f"{dt_max:.3g} s", source=self.config.source, key=key)  # fmt: skip

    # ------------------------------------------------------------------ simulation
    def outputs(self, X: NDArray, run: int = 0, names: tuple[str, ...] | None = None) -> dict[str, NDArray]:
        """The layout's channels (family -> (P, n, k)) of a batch of values X (P, D) of `names` (default the
        unknowns) on run `run`."""
        names = names or self.names
        effects = {n: np.asarray(X[:, j], dtype=float) for j, n in enumerate(names) if "." in n}
        own = [j for j, n in enumerate(names) if "." not in n]
        p = self.parameters(X[:, own], tuple(names[j] for j in own))
        rig = self.rigs[run]
        with np.errstate(all="ignore"):
            if effects or self.kernel:
                from .lumped_effects import kernel_outputs  # the kernel and the effect laws only where used

                disp, acc = kernel_outputs(self, p, effects, run)
            else:
                M, C, K, B0, B1 = self.matrices(p)
                Sq, Sa = self.sensor_rows(p)
                disp, acc = lumped_outputs(M, C, K, B0, B1, rig.u, rig.dt, Sq, Sa)
        out = {"acc": acc, "disp": disp}
        return {f: out[f] for f in self.families}

    def exact_sensitivities(
        self, values: NDArray, run: int = 0, names: tuple[str, ...] | None = None
    ) -> tuple[dict[str, NDArray], dict[str, NDArray]] | None:
        """The layout's channels of run `run` at `values` of `names` (default the unknowns), family -> (n, k), and
        their derivatives family -> (n, k, D) per unit of each parameter, through the same modal solution as the
        simulation (`sim.sensitivity.lumped_sensitivities`); None where that does not apply (effects, the kernel,
        nearly repeated modes)."""
        names = tuple(names or self.names)
        rig = self.rigs[run]
        if self.kernel or any("." in n for n in names) or np.ndim(rig.u) != 2:
            return None
        X, h = stencil(values)  # the rig, then +h_j, then -h_j on parameter j
        p = self.parameters(X, names)
        with np.errstate(all="ignore"):
            got = lumped_sensitivities(
                *self.matrices(p), np.asarray(rig.u, dtype=float), rig.dt, *self.sensor_rows(p), h
            )
        if got is None:
            return None
        disp, acc, ddisp, dacc = got
        out, sens = {"acc": acc, "disp": disp}, {"acc": dacc, "disp": ddisp}
        return {f: out[f] for f in self.families}, {f: sens[f] for f in self.families}

    @property
    def channel_names(self) -> tuple[str, ...]:
        return tuple(s.name for f in self.families for s in self.config.layout if s.family == f)

    def objectives(self, references: tuple[dict[str, NDArray], ...]) -> list[Objective]:
        offsets = self.config.data.offsets == "identify"
        return [Objective(name="wls", reference=r, sigma=w, offsets=offsets)
                for r, w in zip(references, self.weights, strict=True)]  # fmt: skip

    def residual_channels(self, reference) -> NDArray:
        return np.concatenate([o.entry_channels() for o in self.objectives(reference)])

    @property
    def residual_samples(self) -> int:
        return int(sum(r.t.size for r in self.rigs) * len(self.channel_names))

    def reference(self, run: int) -> tuple[dict[str, NDArray], ...]:
        if not self.source.simulated:
            return tuple(r.measured for r in self.rigs)
        rng = run_streams(self.config.identify.seed, run).noise
        return (measurement_noise(self.clean, self.drawn, rng),)

    def problem(self, reference: tuple[dict[str, NDArray], ...], box: Box | None = None) -> Problem:
        """The wls problem over the unknowns (or over `box`: any parameters, their bounds)."""
        objectives = self.objectives(reference)
        box = box or self.box

        def residuals(X: NDArray) -> NDArray:
            return np.concatenate(
                [o.residuals(self.outputs(X, i, box.names)) for i, o in enumerate(objectives)], axis=-1
            )

        def cost_and_residuals(X: NDArray) -> tuple[NDArray, NDArray]:
            r = residuals(X)
            return np.mean(r**2, axis=-1), r

        def linearised(x: NDArray) -> tuple[float, NDArray, NDArray] | None:
            rs, Js = [], []
            for i, o in enumerate(objectives):
                got = self.exact_sensitivities(x, i, box.names)
                if got is None:
                    return None
                rs.append(o.residuals({f: v[None] for f, v in got[0].items()})[0])
                Js.append(o.residual_jacobian(got[1]))
            r = np.concatenate(rs)
            return float(np.mean(r**2)), r, np.concatenate(Js)

        exact = not self.kernel and not any("." in n for n in box.names)
        return Problem(box.lower, box.upper, lambda X: cost_and_residuals(X)[0], cost_and_residuals,
                       names=box.names, linearised=linearised if exact else None)  # fmt: skip

    # ------------------------------------------------------------------ the bound and identifiability
    def information(self, at: NDArray, rel_step: float = 1e-5) -> NDArray:
        """Fisher information (D, D) of the relative unknowns at `at`, summed over the runs: exact sensitivities
        (`exact_sensitivities`) where they apply, else central differences of the simulation."""
        at = np.asarray(at, dtype=float)
        D = at.size
        exact = [self.exact_sensitivities(at, run) for run in range(len(self.weights))]
        if all(e is not None for e in exact):
            F = np.zeros((D, D))
            for (_, sens), w in zip(exact, self.weights, strict=True):
                for f, dz in sens.items():
                    S = np.moveaxis(dz, -1, 0) * np.abs(at)[:, None, None] / w[f][None, None, :]
                    if self.config.data.offsets == "identify":  # what the profiled offsets leave (Schur complement)
                        S = S - S.mean(axis=1, keepdims=True)
                    S = S.reshape(D, -1)
                    F += S @ S.T
            return F
        h = rel_step * np.maximum(np.abs(at), 1e-12)
        X = central_points(at, h)
        F = np.zeros((D, D))
        for run, w in enumerate(self.weights):
            for f, z in self.outputs(X, run).items():
                S = (z[:D] - z[D:]) / (2 * h[:, None, None]) * np.abs(at)[:, None, None] / w[f][None, None, :]
                if self.config.data.offsets == "identify":  # what the profiled offsets leave (the Schur complement)
                    S = S - S.mean(axis=1, keepdims=True)
                S = S.reshape(D, -1)
                F += S @ S.T
        return F

    def bound(self, at: NDArray | None = None) -> CramerRao:
        if at is None:
            at = self.box.truth if self.box.truth is not None else self.box.nominal
        bound = bound_from_information(self.names, at, self.information(at))
        if self.source.simulated and not any(np.any(s > 0) for s in self.drawn.values()):
            bound = CramerRao(bound.names, bound.values, bound.fisher, np.zeros_like(bound.re_sd_percent), 0.0,
                              bound.identifiable, bound.condition)  # fmt: skip
        return bound

    def free_directions(self, bound: CramerRao) -> list[dict[str, float]]:
        """The combinations of unknowns the data cannot separate: null vectors of the correlation-scaled information,
        as relative changes per unknown (largest component 1), small components dropped."""
        F = bound.fisher
        scale = np.sqrt(np.clip(np.diag(F), 1e-300, None))
        corr = F / scale[:, None] / scale[None, :]
        eig, vec = np.linalg.eigh(corr)
        out = []
        for j in np.flatnonzero(eig < NULL_RATIO * eig[-1]):
            v = vec[:, j] / scale  # back to relative parameter changes
            v = v / v[np.argmax(np.abs(v))]
            out.append({n: float(c) for n, c in zip(self.names, v, strict=True) if abs(c) > 0.05})
        zero = np.flatnonzero(np.diag(F) <= 1e-300)
        out += [{self.names[j]: 1.0} for j in zero]
        return out

    def unidentifiable(self, bound: CramerRao) -> str | None:
        """A message naming each free combination of the unknowns and the fixes (None: every unknown is pinned)."""
        found = self.free_directions(bound)
        if not found:
            return None
        parts = [describe_direction(d) for d in found]
        free = tuple(dict.fromkeys(n for d in found for n in d))
        verb = "leaves" if len(parts) == 1 else "leave"
        return (f"the data cannot separate the unknowns: {'; '.join(parts)} {verb} every channel unchanged. "
                f"To identify them: {self.remedies(free)}")  # fmt: skip

    # ------------------------------------------------------------------ vehid simulate
    @classmethod
    def diagnose(cls, config: LumpedConfig, data: tuple[str, ...], validate: tuple[str, ...], log=None, progress=None):
        """The rig's loop (`systems.lumped_diagnosis`) on the measured runs (else data.files); `progress` hears of
        its steps."""
        from .lumped_diagnosis import diagnose_rig  # the loop's machinery only for `vehid diagnose`

        return diagnose_rig(cls, config, data or config.data_runs(), validate, log, progress=progress)

    @classmethod
    def write_simulation(cls, config, target: Path, seed: int, road=None, origin: str = "") -> Simulated:
        """The configured rig with run 0's noise of `seed` (on the inputs and time grid of the file `road`, when given:
        its road columns, and its force with a measured actuator): CSV with t, every sensor (layout order), the
        inputs."""
        system = cls(config, DataSource())
        if road is not None:
            measured = config._relocated({"road": config.road.model_copy(update={"input": "measured"})})
            system.rigs = (read_rig_run(measured, road, (), cls.configured_inputs),)
            system.check_time_step(system.rigs[0].dt, f"{road}: time step")
        rig = system.rigs[0]
        clean = system.outputs(system.box.nominal[None, :], 0)
        clean = {f: v[0] for f, v in clean.items()}
        sigma = {f: system.noise.drawn(f, clean[f]) for f in system.families}
        noisy = measurement_noise(clean, sigma, run_streams(seed, 0).noise)
        columns = {n: noisy[f][:, i] for f in system.families
                   for i, n in enumerate(s.name for s in config.layout if s.family == f)}  # fmt: skip
        names = ["t", *(s.name for s in config.layout), *config.input_names]
        table = np.column_stack([rig.t, *(columns[s.name] for s in config.layout), rig.u])
        comments = [f"vehid {__version__} {origin}".rstrip(), f"config sha256 {config.digest()}",
                    f"noise {config.noise.describe()}, seed {seed}, inputs from {rig.source}"]  # fmt: skip
        write_csv(target, names, table, comments)
        summary = f"{rig.t.size} samples at dt = {rig.dt * 1e3:g} ms, {len(config.layout)} channels"
        from .lumped_plots import trace

        return Simulated(trace(system, 0, noisy, clean), summary, f"{cls.name}: {config.noise.describe()}")

    @classmethod
    def plot_simulation(cls, simulated: Simulated, path: Path) -> None:
        """The inputs, then every channel simulated (noisy) over the configured rig's clean response."""
        from .lumped_plots import plot_trace

        plot_trace(simulated.run, path, f"Responses of the sensors: {simulated.title}", "measured (noisy)",
                   "clean (configured rig)")  # fmt: skip

    @classmethod
    def figures(cls, campaigns, files, out_dir: Path) -> list[Path]:
        """Per campaign, every channel against the rig at the estimate (`systems.lumped_plots`)."""
        from .lumped_plots import campaign_figures

        return campaign_figures(cls, campaigns, files, out_dir)


def describe_direction(direction: dict[str, float]) -> str:
    """'ms, mu, ks scaled by one factor', or the relative changes that cancel ('ks +1, cs -0.5 (relative)')."""
    values = np.array(list(direction.values()))
    if len(values) > 1 and np.allclose(values, values[0], rtol=0.05):
        return f"{', '.join(direction)} scaled by one factor"
    if len(values) == 1:
        return f"{next(iter(direction))} (the channels do not depend on it)"
    return "relative changes " + ", ".join(f"{n} {v:+.3g}" for n, v in direction.items())


def read_rig_run(config: LumpedConfig, path: str | Path, families: tuple[str, ...], inputs: Callable) -> RigRun:
    """A measured run: the layout's channels and the inputs (measured ones read, configured ones on its grid)."""
    data = config.data
    sensors = [s.name for f in families for s in config.layout if s.family == f]
    delays = dict(zip(config.inputs, config.delays(), strict=True))
    measured_inputs = [n for n in config.input_names if (n == "force" and config.road.actuator_force == "measured")
                       or (n != "force" and config.road.input == "measured")
                       or (config.road.input == "track" and n == config.inputs[0])]  # fmt: skip
    ours = sensors + measured_inputs
    family = {s.name: s.family for s in config.layout} | dict.fromkeys(config.inputs, "disp")
    units = {n: data.units.get(n) or data.units.get(family.get(n, ""), "") for n in ours}
    units = {n: u for n, u in units.items() if u}
    record = read_record(path, {n: data.channels.get(n, n) for n in ours}, units, time=data.time,
                         window=data.window, rate=data.rate, time_unit=data.time_unit)  # fmt: skip
    sign = {n: (-1.0 if n in data.invert else 1.0) for n in ours}
    outputs = {}
    for f in families:  # none: the inputs alone (vehid simulate --road)
        names = [s.name for s in config.layout if s.family == f]
        outputs[f] = np.column_stack([sign[n] * record.channel(n) for n in names])
    t = record.t - record.t[0]
    configured = None
    columns = []
    for j, name in enumerate(config.input_names):
        if name in measured_inputs:
            columns.append(sign[name] * record.channel(name))
        elif config.road.input == "track" and name in delays:  # a later wheel on the measured track
            first = sign[config.inputs[0]] * record.channel(config.inputs[0])
            columns.append(np.interp(t - delays[name], t, first, left=first[0]))
        else:
            if configured is None:
                configured = inputs(config, t)
            columns.append(configured[:, j])
    return RigRun(t, np.column_stack(columns), outputs, str(path))


def road_profile(config: LumpedConfig, t: NDArray, delay: float = 0.0) -> NDArray:
    """The configured road (n,) [m] under a wheel that meets it `delay` seconds after the first: the chirp, the bump
    and the random road (experiment stream) summed."""
    road = config.road
    y = np.zeros(t.size)
    end = float(t[-1]) if t.size else 0.0
    if road.chirp is not None:
        c = road.chirp
        y += chirp(t - delay, c.f0, c.f1, c.amplitude, c.start, c.duration or end - c.start, c.fade)
    if road.bump is not None:
        b = road.bump
        y += b.height * bump_unit(b.shape, road.V * (t - delay - b.start_time), b.length, b.plateau)
    if road.random is not None:
        y += RandomProfile(road.random, experiment_rng(config.identify.seed)).height(0, road.V * (t - delay))
    return y


def force_profile(config: LumpedConfig, t: NDArray) -> NDArray:
    """The configured actuator force (n,) [N] (zero without one)."""
    f = config.road.force
    if f is None:
        return np.zeros(t.size)
    end = float(t[-1]) if t.size else 0.0
    return chirp(t, f.f0, f.f1, f.amplitude, f.start, f.duration or end - f.start, f.fade)
