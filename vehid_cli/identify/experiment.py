"""An experiment: the configured car on a sampled road, with its sensors, noise and random streams.

This is where a config becomes arrays: the time grid, the road under each tyre (from bumps, a random
road or a measurement file), the nominal car. Random streams come from the campaign seed through
``SeedSequence.spawn``: one stream for the experiment itself (a random road), and one per run, which
splits into a noise stream and an optimizer stream. Run i gets the same streams whatever the number
of runs or the number of worker processes.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from functools import cached_property, partial
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..config import Config
from ..core.allocator import hand_back_freed_memory, release_free_pages
from ..core.errors import InputError
from ..core.streams import experiment_rng
from ..io.measurement import read_measurement, time_grid
from ..models.effects import check_names
from ..models.fullcar import N_DOF, FullCarMatrices, assemble, parameter_batch
from ..models.noise import NoiseModel, add_channel_noise
from ..models.road import road_function
from ..models.sensors import Layout
from ..sim.kernel import available_cores, in_parallel
from ..sim.linear import Response, simulate, simulate_columns
from ..sim.nonlinear import BLOCK_SAMPLES, effects_blocks, simulate_effects
from ..sim.sensitivity import car_output_matrices, central_slopes, linear_sensitivities, stencil

MIN_SAMPLES_PER_PERIOD = 10  # of the fastest undamped mode (the wheel hop)
BlockSink = Callable[[int, dict, dict], None]  # (first sample, family -> (b, k) channels, -> (b, k, D) derivatives)
CHUNK_BYTES = 40 * 2**20  # the full response of a batch of cars simulated at once, at most (see Experiment.outputs):
# 2 cars of a 60 s record at 1 kHz (18 MB each), one per core (3 at 64 MB: the 60 s diagnosis peaked 37 MB higher)
LONG_BLOCKS = 4  # a record longer than this many blocks of BLOCK_SAMPLES is long: freed memory handed back
BLOCKED_FROM = LONG_BLOCKS  # a record longer than this many blocks runs the RK4 kernel in time blocks. (From 2, the
# long record's 5000-sample screening window too: its candidate threads' peak ~10 MiB lower, but each evaluation
# 1.5x slower on 4-13 cars, the setup repeated per thread: the 60 s diagnosis 1.3-1.6x the wall)


def _cars(values: Mapping[str, ArrayLike] | None) -> int | None:
    """The number of cars of a one-dimensional batch of values (every array 1-D, of one length), else None."""
    arrays = [np.asarray(v) for v in (values or {}).values()]
    sizes = {a.shape[0] for a in arrays if a.ndim == 1}
    if len(sizes) != 1 or any(a.ndim > 1 for a in arrays):
        return None
    return sizes.pop()


@dataclass(frozen=True)
class Experiment:
    """The configured car on a sampled road. Simulates any batch of parameter sets on that road."""

    config: Config
    t: NDArray  # (n,) [s]
    road: NDArray  # (n, 4) [m]
    road_source: str  # "config" or the measurement file the road came from
    chunk_bytes: int = CHUNK_BYTES  # the full responses of the cars `outputs` simulates at once, at most

    def __post_init__(self) -> None:
        """A long record (more than LONG_BLOCKS blocks of BLOCK_SAMPLES, simulated or measured) has the process hand
        freed memory back to the system from then on (`core.allocator.hand_back_freed_memory`: its arrays are tens
        of MB, and a diagnosis's phases otherwise keep each other's freed memory mapped)."""
        if self._long:
            hand_back_freed_memory()

    @property
    def _long(self) -> bool:
        """A long record: more than LONG_BLOCKS blocks of BLOCK_SAMPLES."""
        return self.t.size > LONG_BLOCKS * BLOCK_SAMPLES

    @property
    def long(self) -> bool:
        """A long record: more than LONG_BLOCKS blocks of BLOCK_SAMPLES (forward differences summed in blocks)."""
        return self._long

    @cached_property
    def layout(self) -> Layout:
        """The sensors (config.layout, or the paper's four corners), built once: every simulation reads them."""
        return self.config.sensor_layout()

    @property
    def dt(self) -> float:
        """Time step [s]."""
        return float(self.t[1] - self.t[0])

    @property
    def step(self) -> float:
        """The time-stepping integrator's step [s]: the time step over the configured substeps (the kernel's)."""
        return self.dt / (self.config.simulation.substeps or 1)

    def parameters(self, values: Mapping[str, ArrayLike] | None = None) -> dict[str, NDArray]:
        """All 16 parameters for a batch: the configured car with `values` replacing some of them
        (effect parameters, ``effect.name``, are ignored here: see ``effects``)."""
        car, _ = split_values(values)
        return parameter_batch(self.config.vehicle, car)

    def matrices(self, values: Mapping[str, ArrayLike] | None = None) -> FullCarMatrices:
        """M, C, K, B, G for a batch of cars."""
        return assemble(self.parameters(values))

    def effects(self, values: Mapping[str, ArrayLike] | None = None) -> dict[str, dict[str, ArrayLike]]:
        """The effects of a batch: the declared ones (vehicle.effects) with `values` named ``effect.param``
        replacing some parameters; naming a parameter of an undeclared effect adds that effect (its other
        parameters at their defaults)."""
        _, extra = split_values(values)
        out: dict[str, dict[str, ArrayLike]] = {k: dict(v) for k, v in self.config.vehicle.effect_values().items()}
        for key, value in extra.items():
            effect, _, name = key.partition(".")
            out.setdefault(effect, {})[name] = value
        check_names(out)
        return out

    def simulate(self, values: Mapping[str, ArrayLike] | None = None) -> Response:
        """Clean responses of a batch of cars (the configured car when `values` is None).

        `values` maps vehicle parameter names (``m``, ``a1``, ...) and effect parameters (``hysteresis.alpha_f``)
        to scalars or arrays of one batch shape. Without effects and with a linear integrator (exact, newmark,
        exact-reference) this is the linear path of ``sim.linear``; with effects, or integrator rk4, or
        substeps > 1, the compiled kernel of ``sim.nonlinear`` at the configured integrator (never chosen
        silently: effects with a linear-only integrator are an error).
        """
        sim = self.config.simulation
        effects = self.effects(values)
        p = self.parameters(values)
        points = self.layout.points(p)
        if self._linear(effects):
            return simulate(assemble(p), self.road, self.dt, sim.integrator, points)
        if sim.integrator not in ("rk4", "newmark"):
            raise ValueError(
                f"effects {sorted(effects)} need simulation.integrator rk4 or newmark, not '{sim.integrator}'"
            )
        return simulate_effects(
            assemble(p), p["cf"], p["cr"], effects, self.road, self.dt, sim.integrator, sim.substeps or 1, points
        )

    def _linear(self, effects: Mapping[str, object]) -> bool:
        """Whether a batch with these effects runs on the linear path of ``sim.linear``."""
        sim = self.config.simulation
        return not effects and sim.integrator != "rk4" and (sim.substeps or 1) == 1

    def read(self, response: Response) -> dict[str, NDArray]:
        """The layout's channels of a response: family (acc, disp) -> (..., n, k)."""
        return self.layout.read(response)

    def outputs(self, values: Mapping[str, ArrayLike] | None = None) -> dict[str, NDArray]:
        """The layout's channels of a batch of cars (`simulate`'s values): family -> (..., n, k).

        A long record simulates a one-dimensional batch in chunks of cars, so that the full response of a chunk
        (coordinates, velocities, accelerations and every body point, about 45 columns per sample) stays within
        CHUNK_BYTES: a 60 s run at 1 kHz holds 20 MB of it per car. Each car's numbers are the same either way.
        The exact linear car (what identification runs most) computes only the layout's channels, the same numbers
        as `read(simulate(values))` at a fraction of the cost (sim.linear.simulate_columns)."""
        if self.config.simulation.integrator == "exact" and self._linear(self.effects(values)):
            p = self.parameters(values)
            columns = simulate_columns(
                assemble(p), self.road, self.dt, self.layout.column_groups, "exact", self.layout.points(p)
            )
            return self.layout.read_columns(columns)
        if self.blocked(values):
            return self._read_blocks(values)
        P = _cars(values)
        if P is None:
            return self.read(self.simulate(values))
        chunk = self.cars_per_chunk
        if P <= chunk:
            return self.read(self.simulate(values))
        parts = []
        for start in range(0, P, chunk):
            part = {k: (v[start : start + chunk] if np.ndim(v) == 1 else v) for k, v in (values or {}).items()}
            parts.append(self.read(self.simulate(part)))
        return {f: np.concatenate([p[f] for p in parts]) for f in parts[0]}

    def simulate_blocks(self, values: Mapping[str, ArrayLike] | None = None) -> Iterator[tuple[int, Response]]:
        """`simulate(values)` in time blocks on the RK4 kernel's path (`sim.nonlinear.effects_blocks`): yields (first
        sample, the Response of the block's samples), the same numbers, one block's trajectories held at a time."""
        sim = self.config.simulation
        if sim.integrator != "rk4" or self._linear(self.effects(values)):
            raise ValueError("only the RK4 kernel's path is simulated in time blocks")
        p = self.parameters(values)
        return effects_blocks(assemble(p), p["cf"], p["cr"], self.effects(values), self.road, self.dt,
                              sim.substeps or 1, self.layout.points(p))  # fmt: skip

    def blocked(self, values: Mapping[str, ArrayLike] | None = None) -> bool:
        """Whether `outputs` runs the RK4 kernel in time blocks (`simulate_blocks`): a record of more than
        BLOCKED_FROM blocks of BLOCK_SAMPLES on the kernel's RK4 path."""
        sim = self.config.simulation
        if self.t.size <= BLOCKED_FROM * BLOCK_SAMPLES or sim.integrator != "rk4" or self.road.ndim != 2:
            return False
        return not self._linear(self.effects(values))

    def _read_blocks(self, values: Mapping[str, ArrayLike] | None) -> dict[str, NDArray]:
        """The layout's channels of a batch (`outputs`), the RK4 kernel run over the record in time blocks
        (`sim.nonlinear.effects_blocks`): only the channels are kept whole, never the cars' full trajectories (the
        same numbers: the kernel resumes each block where the one before ended, and the layout reads each sample
        alone)."""
        P = _cars(values)
        if P is None:
            return self._read_blocks_of(values)
        # a one-dimensional batch: its cars split over threads, each running its own blocks
        n = self.t.size
        out = {f: np.empty((P, n, len(self.layout.names(f)))) for f in self.layout.families}

        def rows(s: slice) -> None:
            part = {k: (v[s] if np.ndim(v) == 1 else v) for k, v in values.items()}
            self._read_blocks_of(part, {f: y[s] for f, y in out.items()})

        in_parallel(P, rows)
        if self._long:
            release_free_pages()  # the blocks' freed memory back to the system (core/allocator.py)
        return out

    def _read_blocks_of(
        self, values: Mapping[str, ArrayLike] | None, out: dict[str, NDArray] | None = None
    ) -> dict[str, NDArray]:
        """`_read_blocks` of a batch in this thread (the kernel's own split over threads per block would start a
        pool per block: twice the wall of one call at 2048-sample blocks), written into `out` when given."""
        out = {} if out is None else out
        n = self.t.size
        for k0, response in self.simulate_blocks(values):
            part = self.read(response)
            for family, y in part.items():
                if family not in out:
                    out[family] = np.empty(y.shape[:-2] + (n, y.shape[-1]))
                out[family][..., k0 : k0 + y.shape[-2], :] = y
        return out

    @property
    def cars_per_chunk(self) -> int:
        """How many cars `outputs` simulates at once: their full response (about 45 columns per sample) within
        `chunk_bytes` (CHUNK_BYTES unless the experiment was made with less: a long record's screening window), at
        least one car. A record simulated in time blocks holds only the layout's channels of each car (and an
        objective's error and residuals beside them): within `chunk_bytes` of those three copies, and one car per
        core on a long record (more cars at once would only hold more: the blocks already split the cars over the
        cores)."""
        if self.blocked(None):
            per_car = self.t.size * 3 * len(self.layout.sensors) * 8
            return max(1, min(self.chunk_bytes // per_car, available_cores() if self._long else self.chunk_bytes))
        per_car = self.t.size * (3 * N_DOF + 2 * len(self.layout.sensors) + 8) * 8
        return max(1, self.chunk_bytes // per_car)

    def exact_sensitivities(
        self, names: tuple[str, ...] | list[str], values: ArrayLike, sink: BlockSink | None = None
    ) -> tuple[dict[str, NDArray], dict[str, NDArray]] | None:
        """The layout's channels of one car (family -> (n, k)) and their derivatives with respect to the vehicle
        parameters `names` at `values` (family -> (n, k, D), per unit of each parameter), through the same modal
        solution as the simulation (`sim.sensitivity`); None where that path does not apply (effects, another
        integrator, substeps, a non-vehicle unknown, an ill-conditioned or nearly repeated set of modes).

        The dynamics are differentiated exactly; the matrices' derivatives (A, Bs, the body points' rows, the static
        start) come from central differences of their assembly, which is polynomial or rational in the parameters
        (relative error ~1e-10 at a relative step of 1e-6).

        With `sink`, the derivatives are not kept (a long record's are tens of MB): each block of samples is handed
        to `sink(k0, out, sens)` as it is made (first sample k0; family -> (b, k) channels, (b, k, D) derivatives),
        and the derivatives returned are empty; on None the blocks handed over are not to be used."""
        if not self.exact_applies(names):
            return None
        X, h = stencil(values)  # the car, then +h_j, then -h_j on parameter j
        p = self.parameters({n: X[:, j] for j, n in enumerate(names)})
        mats = assemble(p)
        A, Bs = mats.state_space()
        s0 = np.zeros(A.shape[:-1])
        s0[:, :N_DOF] = np.linalg.solve(mats.K, mats.B @ self.road[0][:, None])[..., 0]  # static, first sample
        Call, Dall = car_output_matrices(A, Bs, self.layout.points(p))
        rows = self._channel_rows(Call.shape[-2])
        Cy = np.concatenate([r.T @ Call for r in rows.values()], axis=-2)
        Dy = np.concatenate([r.T @ Dall for r in rows.values()], axis=-2)

        slope = partial(central_slopes, h=h)
        split = None if sink is None else partial(_split_block, rows=rows, sink=sink)

        with np.errstate(all="ignore"):
            Y, dY, ok = linear_sensitivities(
                A[:1], Bs[:1], s0[:1], self.road, self.dt, Cy[:1], Dy[:1], slope(A), slope(Bs), slope(s0),
                slope(Cy), slope(Dy), sink=split,
            )  # fmt: skip
        if not ok[0]:
            return None
        out, sens, first = {}, {}, 0
        for family, r in rows.items():
            k = r.shape[1]
            out[family] = Y[0, :, first : first + k]
            if dY is not None:
                sens[family] = dY[0, :, first : first + k]
            first += k
        return out, sens

    def exact_applies(self, names: tuple[str, ...] | list[str]) -> bool:
        """Whether `exact_sensitivities` can differentiate with respect to `names`: the linear car on the exact path
        (no effects, integrator exact, no substeps), vehicle parameters only."""
        if not self._exact_path:
            return False
        return not any("." in n for n in names) and set(names) <= self._vehicle_names

    @cached_property
    def _exact_path(self) -> bool:
        """The configured car on the exact linear path (no effects, integrator exact, no substeps, one road): asked
        by every linearisation, decided once."""
        sim = self.config.simulation
        return not (self.effects() or sim.integrator != "exact" or (sim.substeps or 1) != 1 or self.road.ndim != 2)

    @cached_property
    def _vehicle_names(self) -> set[str]:
        """The configured car's parameter names."""
        return set(self.config.vehicle.values())

    def _channel_rows(self, columns: int) -> dict[str, NDArray]:
        """Family -> (columns, k): how the layout's channels read the response's columns [q, qd, qdd, disp, acc]
        (`Layout.read` is linear in them, sample by sample). Built once per column count (every linearisation
        asks)."""
        cache = self._channel_rows_cache
        if columns not in cache:
            cache[columns] = self._read_rows(columns)
        return cache[columns]

    @cached_property
    def _channel_rows_cache(self) -> dict[int, dict[str, NDArray]]:
        """`_channel_rows`' matrices by column count (filled on first use)."""
        return {}

    def _read_rows(self, columns: int) -> dict[str, NDArray]:
        """`_channel_rows` computed: the layout read from an identity response."""
        eye = np.eye(columns)
        nb = (columns - 3 * N_DOF) // 2
        d = N_DOF
        fake = Response(t=np.zeros(columns), q=eye[:, :d], qd=eye[:, d : 2 * d], qdd=eye[:, 2 * d : 3 * d],
                        disp=eye[:, 3 * d : 3 * d + nb], acc=eye[:, 3 * d + nb :])  # fmt: skip
        return self.read(fake)

    @cached_property
    def noise(self) -> NoiseModel:
        """The config's noise, resolved once: Eq. 15's level and each channel's absolute floor (the sensor's own
        sigma, else its family's noise.sigma, else NaN: Eq. 15 with noise.level)."""
        cfg = self.config
        own = {s.name: s.sigma for s in cfg.layout or ()}
        floors = {}
        for family in self.layout.families:
            floor = getattr(cfg.noise.sigma, family)
            values = [own.get(name) or floor for name in self.layout.names(family)]
            floors[family] = np.array([np.nan if v is None else v for v in values], dtype=float)
        return NoiseModel(cfg.noise.level, floors)

    def noise_floors(self, family: str) -> NDArray:
        """Absolute noise standard deviation per channel of a family (k,), NaN where Eq. 15 applies."""
        return self.noise.floors[family]


def _split_block(p: int, k0: int, y: NDArray, dy: NDArray, rows: dict[str, NDArray], sink: BlockSink) -> None:
    """A block of `linear_sensitivities`' outputs y (b, ny) and derivatives dy (b, ny, D) handed to `sink` family by
    family (`rows`: family -> (columns, k), in the order of the outputs' columns)."""
    out, sens, first = {}, {}, 0
    for family, r in rows.items():
        k = r.shape[1]
        out[family], sens[family] = y[:, first : first + k], dy[:, first : first + k]
        first += k
    sink(k0, out, sens)


def split_values(values: Mapping[str, ArrayLike] | None) -> tuple[dict[str, ArrayLike], dict[str, ArrayLike]]:
    """Vehicle parameters and effect parameters (dotted ``effect.param`` names) of a batch's values."""
    car, effects = {}, {}
    for key, value in (values or {}).items():
        (effects if "." in key else car)[key] = value
    return car, effects


def build_experiment(config: Config, road_file: str | Path | None = None) -> Experiment:
    """Sample the configured road (or read it from `road_file` / `road.file`), check the time step."""
    vehicle = config.vehicle
    file = road_file if road_file is not None else config.road.file
    if file is not None:
        measured = read_measurement(file, need_responses=False)
        road, source, dt_key = measured.road, str(file), f"{file}: column 't'"
        t = measured.t[0] + np.arange(measured.t.size) * measured.dt  # the uniform grid the file approximates
    else:
        sim = config.simulation
        t = time_grid(sim.duration, sim.dt)
        heights = road_function(config.road, vehicle.L, experiment_rng(config.identify.seed))
        road, source, dt_key = heights(t), "config", "simulation.dt"
    check_time_step(config, float(t[1] - t[0]), dt_key)
    return Experiment(config=config, t=t, road=road, road_source=source)


def check_time_step(config: Config, dt: float, key: str) -> None:
    """Refuse a time step too coarse to resolve the fastest mode (the wheel hop) of the configured car."""
    values = config.vehicle.values()
    with np.errstate(all="ignore"):
        mats = assemble(values)
    if not all(np.all(np.isfinite(X)) for X in (mats.M, mats.C, mats.K)):
        worst = max(values, key=lambda n: abs(values[n]))
        raise InputError(
            f"the configured car's mass, damping or stiffness matrix overflows; the largest value is "
            f"vehicle.{worst} = {values[worst]:g}: expected physical values in SI units",
            source=config.source,
            key=f"vehicle.{worst}",
        )
    for matrix, family in ((mats.M, ("m", "mf", "mr", "Ix", "Iy")), (mats.K, ("kf", "kr", "ktf", "ktr"))):
        eig = np.linalg.eigvalsh(matrix)
        if not eig[0] > 1e-12 * eig[-1]:  # singular or indefinite: no static equilibrium, no modes
            worst = min(family, key=lambda n: abs(values[n]))
            kind = "mass" if family[0] == "m" else "stiffness"
            raise InputError(
                f"the configured car's {kind} matrix is singular (condition beyond 1e12): the smallest {kind} is "
                f"vehicle.{worst} = {values[worst]:g}: expected physical values in SI units",
                source=config.source,
                key=f"vehicle.{worst}",
            )
    omega = mats.natural_frequencies()
    f_max = float(omega[-1]) / (2 * math.pi)
    dt_max = 1.0 / (MIN_SAMPLES_PER_PERIOD * f_max)
    if dt > dt_max * (1 + 1e-9):
        hint = ""
        if "time step" in key and dt * 1e-3 <= dt_max:  # a measured run whose step fits only in milliseconds
            hint = (
                f"; the time stamps step by {dt:g}, which fits a logger at {1 / (dt * 1e-3):g} Hz if they are in "
                "ms: set data.time_unit: ms"
            )
        raise InputError(
            f"time step {dt:g} s is too coarse for the wheel-hop mode at {f_max:.2f} Hz: use dt <= {dt_max:.3g} s "
            f"({MIN_SAMPLES_PER_PERIOD} samples per period of the fastest mode){hint}",
            source=config.source,
            key=key,
        )


@dataclass(frozen=True)
class SimulatedRun:
    """Clean responses of the configured car and their noisy measurement (Eq. 15, or the configured noise floors)."""

    experiment: Experiment
    clean: Response
    clean_channels: dict[str, NDArray]  # family -> (n, k) the layout's channels, clean
    channels: dict[str, NDArray]  # family -> (n, k) noisy
    sigma: dict[str, NDArray]  # family -> (k,) the noise standard deviation drawn
    noise_level: float

    @property
    def acc(self) -> NDArray | None:
        """Noisy accelerometer channels (n, k) [m/s²], None without accelerometers."""
        return self.channels.get("acc")

    @property
    def disp(self) -> NDArray | None:
        """Noisy displacement and deflection channels (n, k) [m], None without them."""
        return self.channels.get("disp")


DIVERGED_FACTOR = 100.0  # a body moving more than this many times the road's height has diverged


def simulate_measurement(experiment: Experiment, rng: np.random.Generator) -> SimulatedRun:
    """Simulate the configured car and add noise to each channel of its layout (accelerations first, then
    displacements; see `measurement_noise`)."""
    clean = experiment.simulate()
    road = np.max(np.abs(experiment.road)) if np.size(experiment.road) else 0.0
    limit = DIVERGED_FACTOR * max(road, 1e-3)
    heights = clean.q[:, [0, 3, 4, 5, 6]]  # bounce and wheel hops [m]
    if not (np.all(np.isfinite(heights)) and np.max(np.abs(heights)) <= limit):
        k = int(np.argmax(~np.isfinite(heights).all(axis=1) | (np.abs(heights) > limit).any(axis=1)))
        raise InputError(
            f"the simulation diverged at t = {clean.t[k]:.4g} s (body or wheel displacement beyond {limit:.3g} m, "
            f"{DIVERGED_FACTOR:g} times the road's largest height): the configured effects are too stiff for "
            f"this time step (an effect bottoming out, e.g. a gas column shorter than the strut's stroke); "
            "check vehicle.effects or use a smaller simulation.dt",
            source=experiment.config.source,
            key="simulation.dt",
        )
    channels = experiment.read(clean)
    sigma = {f: clean_sigma(experiment, f, channels[f]) for f in channels}
    noisy = measurement_noise(channels, sigma, rng)
    return SimulatedRun(experiment, clean, channels, noisy, sigma, experiment.config.noise.level)


def clean_sigma(experiment: Experiment, family: str, clean: NDArray) -> NDArray:
    """The noise standard deviation (k,) drawn for a family's clean channels (n, k) (`NoiseModel.drawn`)."""
    return experiment.noise.drawn(family, clean)


def measurement_noise(
    clean: dict[str, NDArray], sigma: dict[str, NDArray], rng: np.random.Generator
) -> dict[str, NDArray]:
    """Noisy copies of the clean channels, drawn family by family in the order given (acc, then disp: the paper's
    runs see the same draws as before layouts existed)."""
    return {f: add_channel_noise(clean[f], sigma[f], rng) for f in clean}
