"""Close the loop on a damper test bench: fit the declared damper model to a measured force, rank the
library's effects as candidates, add the best accepted one, re-fit, repeat (the same loop as the car's).

* J is Fleps-Dezasse Eq. 7 (SPEC section 4): mean squared force error over the variance of the measured force,
  on the training run; the validation J is the mean of Eq. 7 over the held-out runs (``--validate``, else the
  config's ``data.validate``), else over held-out blocks of the training run.
* The noise sigma of the force is not known on a bench: the test is the likelihood ratio with the noise
  variance profiled out, LR = n_eff ln(J_before / J_with), over n_eff = n (1 - rho) / (1 + rho) effective
  samples, rho the lag-1 autocorrelation of the current model's residual. Model error on a bench is smooth,
  not white; counting every sample as independent would make every candidate significant (Bartlett's
  correction for an AR(1) residual). Confidence intervals are inflated by the same factor.
* A candidate must also lower the validation J by MIN_GAIN: on real data any flexible term lowers it a
  little, and a 2 % gain is the least worth a new parameter in a damper model.

Candidates (canonical names, SPEC section 5): ``hysteresis``, ``asymmetric_damping``, ``damper_lag`` and
``coulomb_friction`` from the effect library (their bench forms, models/effects/), ``gas_spring`` as the
damper's own gas force k1 (x - x0) and ``backlash`` as its exact play of width ``gap`` (models/damper.py).
An effect the declared model already has (friction in Bingham or Bouc-Wen, hysteresis in Bouc-Wen, a gas
force or a gap among the unknowns) is not a candidate. Search ranges scale with the data: the force, stroke
and velocity standard deviations F, X, V.
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ...config import DamperConfig
from ...core.errors import InputError
from ...core.progress import ProgressHook
from ...core.streams import run_streams
from ...diagnose.attribution import (
    ALPHA,
    Candidate,
    Fit,
    candidate_ranges,
    effect_candidate,
    fit_intervals,
    lsq_fit,
    parameter_candidate,
)
from ...diagnose.bench_law import BenchLaw, bench_law
from ...diagnose.holdout import HOLDOUT_EVERY, block_size, holdout_blocks
from ...diagnose.loop import close
from ...diagnose.quality import assess_bench
from ...diagnose.residuals import analyse_bench, autocorrelation
from ...diagnose.result import Diagnosis, ModelReport
from ...diagnose.subject import Subject
from ...models.bench import BenchHistory
from ...models.effects import LIBRARY, BenchScale
from ...optimizers import get_optimizer
from ...optimizers.base import Problem
from .bench import MEASURED, configured_spec, load_measured
from .fit import PENALTY_FACTOR, DamperSpec

MAX_ROUNDS = 4
MIN_GAIN = 0.02
CANDIDATE_BUDGET = 200
REFIT_BUDGET = 800
FRICTIONLESS = ("viscous", "gas_spring")  # models without a friction term of their own
BENCH_PARAMETER_RANGE = (0.5, 2.0)  # a fixed damper parameter freed as a candidate: this factor range of its value


def bench_candidates(spec: DamperSpec, history: BenchHistory, declared_unknowns) -> dict[str, Candidate]:
    """The bench form of each registered effect the declared damper lacks (its ranges scaled to the data), then the
    damper model's fixed parameters as ``parameter:<name>``."""
    X = max(float(np.std(history.x)), 1e-6)
    V = max(float(np.std(history.v)), 1e-6)
    scale = BenchScale(
        F=float(np.std(history.force)), X=X, V=V, dt=float(history.dt),
        yields=(0.03 * X, 0.1 * X, 0.3 * X, 0.8 * X),  # loop widths from 3 % to 80 % of the stroke's spread
        velocities=(0.02 * V, 0.1 * V, 0.5 * V), x_mean=float(np.mean(history.x)),
    )  # fmt: skip
    out = [effect_candidate(name, e.bench_candidate(scale)) for name, e in LIBRARY.items() if e.bench_candidate]
    declared = set(spec.effects)
    if "k1" in declared_unknowns or spec.values.get("k1", 0.0) != 0.0:
        declared.add("gas_spring")
    if "gap" in declared_unknowns or spec.values.get("gap", 0.0) != 0.0:
        declared.add("backlash")
    if spec.model in ("bouc_wen", "generalized_bouc_wen"):
        declared.add("hysteresis")
    if spec.model not in FRICTIONLESS:
        declared.add("coulomb_friction")
    if spec.model == "force_map":  # a table over velocity holds any compression/rebound difference
        declared.add("asymmetric_damping")
    out += [
        parameter_candidate(n, v, "damper", {n: tuple(sorted(f * v for f in BENCH_PARAMETER_RANGE))})
        for n, v in spec.values.items()
        if n in spec.names and n not in declared_unknowns and v != 0.0 and n not in ("k1", "x0", "gap")
    ]  # the damper model's fixed parameters (its gas force and play are the gas_spring and backlash candidates)
    return {c.effect: c for c in out if c.effect not in declared}


def _effects_of(names) -> tuple[str, ...]:
    return tuple(dict.fromkeys(n.partition(".")[0] for n in names if "." in n))


@dataclass(frozen=True)
class BenchRuns:
    """The measured runs of a bench diagnosis: the training run (its file and history), the held-out runs (their
    files, and histories by stem), and the training samples kept out of the held-out blocks (None: all, when there
    are held-out runs)."""

    file: str | Path
    train: BenchHistory
    validate_files: tuple[str | Path, ...]
    held_out: dict[str, BenchHistory]
    keep: NDArray | None

    @classmethod
    def load(
        cls, config: DamperConfig, data_file: str | Path | None, validate_files: tuple[str | Path, ...] | None
    ) -> BenchRuns:
        """`data_file` (else the config's data.file) and `validate_files` (else the config's data.validate), read
        with the config's columns and units."""
        data_file = data_file if data_file is not None else (config.data.file if config.data is not None else None)
        if data_file is None:
            raise InputError("diagnose needs measured data: give --data FILE or data.file", source=config.source)
        train = load_measured(config, data_file)
        if validate_files is None:
            validate_files = tuple(config.data.validate_files) if config.data is not None else ()
        held_out = {Path(str(p)).stem: load_measured(config, p) for p in validate_files}
        keep = None if held_out else ~holdout_blocks(train.t.size)
        return cls(data_file, train, tuple(validate_files), held_out, keep)

    @property
    def validation_source(self) -> str:
        """Where the validation J comes from, for the report."""
        if self.held_out:
            return "held-out runs: " + ", ".join(os.path.normpath(str(p)) for p in self.validate_files)
        n = self.train.t.size
        return f"held-out blocks of {self.file} (every {HOLDOUT_EVERY}th block of {block_size(n)} samples)"


def noise_sigma(train: BenchHistory) -> float:
    """The force's noise sigma [N] estimated from the training run (third differences), at least 1e-9 of its spread."""
    sigma = float(MEASURED.estimated("force", train.force[:, None])[0])
    return max(sigma, 1e-9 * float(np.std(train.force)))


@dataclass(frozen=True)
class BenchLoop:
    """The damper's side of the loop: Eq. 7's J over any unknowns (the declared ones at the configured values, the
    candidates' at their starts) on the training and the held-out data, the LR test and interval scale over the
    effective samples of an AR(1) residual, and the report of a fit."""

    runs: BenchRuns
    spec: DamperSpec
    declared_names: tuple[str, ...]
    starts: dict[str, float]
    limits: dict[str, tuple[float, float]]
    substeps: int
    sigma: float  # the force's noise sigma [N]

    @property
    def residual_count(self) -> int:
        """Training samples."""
        keep = self.runs.keep
        return int(self.runs.train.t.size if keep is None else keep.sum())

    def spec_for(self, names) -> DamperSpec:
        """The configured damper with the effects among `names` (their parameters at the defaults and starts)."""
        spec, starts = self.spec, self.starts
        effects = _effects_of(names)
        values = {f"{e}.{p.name}": p.default for e in effects for p in LIBRARY[e].params}
        values.update({k: v for k, v in starts.items() if k.partition(".")[0] in effects})
        return spec.with_effects(effects, {**values, **{k: v for k, v in spec.values.items() if k in values}})

    def problem_on(self, names: tuple[str, ...], history: BenchHistory, mask: NDArray | None) -> Problem:
        """Eq. 7's J over `names` on `history` (the samples `mask` keeps): squared residuals over the force's
        variance, summed."""
        s = self.spec_for(names)
        substeps = self.substeps
        force = history.force if mask is None else history.force[mask]
        scale = np.sqrt(force.size * np.var(force))  # sum of squared residuals = Eq. 7's J

        def cost_and_residuals(X: NDArray) -> tuple[NDArray, NDArray]:
            with np.errstate(all="ignore"):
                sim = s.simulate_batch(names, X, history, substeps).force
                r = (history.force[None, :] - sim) / scale
                r = r if mask is None else r[:, mask]
                return np.sum(r**2, axis=1), r

        lower = np.array([self.limits[n][0] for n in names], dtype=float)
        upper = np.array([self.limits[n][1] for n in names], dtype=float)
        return Problem(lower, upper, lambda X: cost_and_residuals(X)[0], cost_and_residuals, 1.0, names)

    def problem_for(self, names: tuple[str, ...]) -> tuple[Problem, NDArray]:
        """The training problem over `names` (a finite penalty for unstable candidates) and its start."""
        s = self.spec_for(names)
        start = np.array([self.starts.get(n, s.values.get(n, 0.0)) if n not in self.declared_names else s.values[n]
                          for n in names], dtype=float)  # fmt: skip
        p = self.problem_on(names, self.runs.train, self.runs.keep)
        start = np.clip(start, p.lower, p.upper)
        return _with_penalty(p, start), start

    def validation_J(self, names: tuple[str, ...], x: NDArray) -> tuple[float, dict[str, float] | None]:
        """J on the held-out blocks, or its mean over the held-out runs (and per run)."""
        X = np.asarray(x, dtype=float)[None, :]
        runs = self.runs
        if not runs.held_out:
            c = self.problem_on(names, runs.train, ~runs.keep).cost(X)[0]
            return (float(c) if np.isfinite(c) else float("inf")), None
        per = {k: float(self.problem_on(names, h, None).cost(X)[0]) for k, h in runs.held_out.items()}
        per = {k: (v if np.isfinite(v) else float("inf")) for k, v in per.items()}
        return float(np.mean(list(per.values()))), per

    def n_eff(self, problem: Problem, x: NDArray) -> float:
        """Effective training samples at x: R (1 - rho) / (1 + rho), rho the lag-1 autocorrelation of the residual."""
        _, r = problem.residuals(np.asarray(x, dtype=float)[None, :])
        rho = float(np.clip(autocorrelation(r[0], 1)[1], 0.0, 0.99)) if np.all(np.isfinite(r)) else 0.0
        return self.residual_count * (1.0 - rho) / (1.0 + rho)

    def statistic(self, current: Fit) -> Callable[[float, float], float]:
        """The likelihood ratio against the fit `current`, the noise variance profiled out, over n_eff samples."""
        ne = self.n_eff(self.problem_for(current.names)[0], current.x)
        return lambda J0, J1: float(ne * np.log(J0 / J1)) if 0 < J1 < J0 else 0.0

    def scale(self, f: Fit) -> float:
        """Variance of one residual entry at a fit, AR(1)-inflated."""
        return f.J / max(self.n_eff(self.problem_for(f.names)[0], f.x), 1.0)

    def report(self, f: Fit, effects: Sequence[str]) -> ModelReport:
        """The fit `f` with `effects`: intervals, J, validation J (per held-out run), the residual analysis."""
        train = self.runs.train
        s = self.spec_for(f.names)
        force = s.simulate_batch(f.names, np.asarray(f.x)[None, :], train, self.substeps).force[0]
        ci = fit_intervals(self.problem_for(f.names)[0], f, self.scale(f))
        vJ, per = self.validation_J(f.names, f.x)
        an = analyse_bench(train, force, self.sigma)
        return ModelReport(tuple(effects), f.names, f.x, ci, f.J, an.chi2_per_sample, vJ, None, an, per, f.fixed)


def fit_declared(config: DamperConfig, bench: BenchLoop, refit_budget: int, say: Callable[[str], None]) -> Fit:
    """The declared model: the configured algorithm from the configured values, then a least-squares polish."""
    ident = config.identify
    problem, x0 = bench.problem_for(bench.declared_names)
    budget = ident.budget or ident.algorithm.population * ident.algorithm.iterations
    opt = get_optimizer(ident.algorithm.name, ident.algorithm.population, max(1, budget // ident.algorithm.population))
    res = opt.minimize(problem, run_streams(ident.seed, 0).optimizer, budget=budget, x0=x0)
    fit = lsq_fit(problem, res.x, refit_budget)
    say(f"declared {bench.spec.model}: J = {fit.J:.4g} ({res.evaluations + fit.evaluations} evaluations)")
    return fit


def diagnose_damper(
    config: DamperConfig,
    data_file: str | Path | None = None,
    validate_files: tuple[str | Path, ...] | None = None,
    *,
    alpha: float = ALPHA,
    max_rounds: int = MAX_ROUNDS,
    candidate_budget: int = CANDIDATE_BUDGET,
    refit_budget: int = REFIT_BUDGET,
    log=None,
    progress: ProgressHook | None = None,
) -> Diagnosis:
    """Close the loop for the configured damper on the measured run `data_file` (see the module doc); `progress`
    hears of each step (the declared fit, each candidate tested, each re-fit)."""
    t_start = time.perf_counter()
    say = log or (lambda _msg: None)
    step = progress or (lambda _stage, _done, _total: None)
    runs = BenchRuns.load(config, data_file, validate_files)
    spec = configured_spec(config)
    declared_names = tuple(config.identify.unknowns)
    specs = bench_candidates(spec, runs.train, declared_names)
    effect_limits, starts = candidate_ranges(specs)
    limits = {**config.search_box(), **effect_limits}
    bench = BenchLoop(runs, spec, declared_names, starts, limits, config.bench.substeps, noise_sigma(runs.train))
    step("declared fit", 0, 1)
    fit = fit_declared(config, bench, refit_budget, say)
    before = bench.report(fit, ())
    step("declared fit", 1, 1)
    quality = assess_bench(runs.train, bench.sigma, declared_names, before)
    subject = Subject(
        specs=specs, declared=frozenset(), problem_for=bench.problem_for, validation_J=bench.validation_J,
        residual_count=bench.residual_count, statistic=bench.statistic, scale=bench.scale, min_gain=MIN_GAIN,
    )  # fmt: skip
    d = close(
        subject, fit, before, bench.report, quality, alpha=alpha, max_rounds=max_rounds,
        candidate_budget=candidate_budget, refit_budget=refit_budget, say=say, t_start=t_start,
        chi2_residuals=runs.train.t.size, validation_source=runs.validation_source,
        sigma_source=f"force noise sigma {bench.sigma:.4g} N estimated from the training run (third differences)",
        system="damper", validation_from_file=bool(runs.held_out), unit=config.unit,
        J_definition="Fleps-Dezasse Eq. 7: mean squared force error over the variance of the measured force",
        progress=progress,
    )  # fmt: skip
    if quality.ok and d.at_noise is False:  # what the final model misses, as a law of x and v (and u)
        law = bench_law_of(bench, d.after)
        say(f"the unexplained damper force {law.summary()}")
        d = replace(d, unexplained=law)
    return d


def bench_law_of(bench: BenchLoop, f: ModelReport) -> BenchLaw:
    """The non-parametric law of the force the model `f` misses (diagnose.bench_law): fitted on the training samples,
    judged on the held-out runs (else the held-out blocks)."""
    runs = bench.runs
    spec = bench.spec_for(f.names)

    def arrays(h: BenchHistory, mask: NDArray | None) -> dict[str, NDArray]:
        model = spec.simulate_batch(f.names, np.asarray(f.x)[None, :], h, bench.substeps).force[0]
        out = {"force": h.force, "model": model, "displacement": h.x, "velocity": h.v, "control": h.u}
        return {k: np.asarray(v) if mask is None else np.asarray(v)[mask] for k, v in out.items()}

    train = arrays(runs.train, runs.keep)
    if runs.held_out:
        held = {k: arrays(h, None) for k, h in runs.held_out.items()}
    else:
        held = {"held-out blocks": arrays(runs.train, ~runs.keep)}
    return bench_law(train, held)


def _with_penalty(problem: Problem, start: NDArray) -> Problem:
    """The problem with a finite penalty for unstable candidates: PENALTY_FACTOR x its J at the start."""
    J0 = float(problem.cost(start[None, :])[0])
    penalty = PENALTY_FACTOR * max(J0 if np.isfinite(J0) else 1.0, 1.0)
    return Problem(problem.lower, problem.upper, problem.cost, problem.residuals, penalty, problem.names)
