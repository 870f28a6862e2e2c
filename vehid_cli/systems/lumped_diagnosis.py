"""Close the loop for a linear rig (`vehid diagnose` on a quarter or half car): the declared model fitted by wls on
the measured runs (jointly), by RK4 on the compiled kernel (`systems.lumped_effects`), the effect library's car
forms on the rig's struts and the rig's known parameters as candidates (`parameter:<name>`: a damper off, a spring
not what the config says), held-out blocks (or --validate runs) for the validation J, and the verdict of
`diagnose.loop.close`: a residual the candidates do not explain is `incomplete`, never a tight wrong answer."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..config.lumped import LumpedConfig
from ..core.errors import InputError
from ..core.progress import ProgressHook
from ..core.streams import run_streams
from ..diagnose.attribution import (
    ALPHA,
    CANDIDATE_BUDGET,
    Z95,
    Candidate,
    Fit,
    candidate_ranges,
    chi2_statistic,
    fit_intervals,
    lsq_fit,
    parameter_candidate,
)
from ..diagnose.holdout import HOLDOUT_EVERY, holdout_blocks, masked
from ..diagnose.loop import MAX_ROUNDS, REFIT_BUDGET, close
from ..diagnose.quality import MAX_NOISE_RATIO, MIN_SAMPLES, Quality
from ..diagnose.result import Diagnosis, ModelReport, chi2_limit
from ..diagnose.subject import Subject
from ..identify.source import DataSource
from ..models.effects import LIBRARY
from ..optimizers import get_optimizer
from .base import Box
from .base import System as LumpedSystem  # a systems.lumped.LumpedSystem (which imports this module)
from .lumped_effects import rig_candidates

DAMPING_SPAN = 3.0  # a damping candidate ranges over [0, 3x configured]: a damper off is 0
OTHER_SPAN = (0.2, 5.0)  # masses, stiffnesses: factors of the configured value


def parameter_specs(system: LumpedSystem) -> dict[str, Candidate]:
    """Every configured parameter not among the unknowns, as a candidate (its group: the rig's `groups`)."""
    values = system.config.parameter_values()
    ranges = system.config.ranges()
    out = {}
    for group, names in system.groups:
        for n in names:
            v = values[n]
            if n in system.names or v == 0.0 or (group == "actuator" and "force" not in system.config.input_names):
                continue
            lo, hi = (0.0, DAMPING_SPAN * v) if group == "dampers" else (OTHER_SPAN[0] * v, OTHER_SPAN[1] * v)
            if group == "actuator":  # the recorded force's gain, its sign included
                lo, hi = -OTHER_SPAN[1] * abs(v), OTHER_SPAN[1] * abs(v)
            low, high = ranges.get(n, (lo, hi))
            c = parameter_candidate(n, v, group, {n: (max(lo, low), min(hi, high))})
            out[c.effect] = c
    return out


@dataclass(frozen=True)
class RigLoop:
    """The rig's side of the loop: problems over any parameters, the validation J, the report of a fit."""

    system: LumpedSystem
    ref: tuple
    keep: NDArray | None  # training residual entries (None: all; a --validate run holds the validation)
    validation: tuple[LumpedSystem, tuple, NDArray | None]  # the system, reference and entries the validation J uses
    specs: dict[str, Candidate]

    def box(self, system: LumpedSystem, names: tuple[str, ...]) -> Box:
        own = system.box
        lo, hi, x0 = list(own.lower), list(own.upper), list(own.nominal)
        values = system.config.parameter_values()
        limits, starts = candidate_ranges(self.specs)
        for n in names[len(own.names) :]:
            a, b = limits[n]
            if "." in n:  # an effect's parameter: its candidate's start, else the library's default
                effect, _, param = n.partition(".")
                base = param[:-2] if param[-2:] in ("_f", "_r") else param
                default = LIBRARY[effect].defaults().get(param, LIBRARY[effect].defaults().get(base, 0.0))
                v = starts.get(n, default)
            else:
                v = values[n]
            lo.append(a)
            hi.append(b)
            x0.append(float(np.clip(v, a, b)))
        return Box(tuple(names), np.array(lo), np.array(hi), np.array(x0), None)

    def problem_for(self, names: tuple[str, ...]):
        box = self.box(self.system, names)
        return masked(self.system.problem(self.ref, box), self.keep), box.nominal

    def validation_J(self, names: tuple[str, ...], x: NDArray) -> tuple[float, None]:
        system, ref, entries = self.validation
        problem = masked(system.problem(ref, self.box(system, names)), entries)
        cost = problem.cost(np.asarray(x, dtype=float)[None, :])[0]
        return (float(cost) if np.isfinite(cost) else float("inf")), None

    def report(self, f: Fit, effs: Sequence[str]) -> ModelReport:
        ci = fit_intervals(self.problem_for(f.names)[0], f, f.J)
        truth = self.system.box.truth
        nre = bound = None
        if truth is not None:
            n = len(truth)
            nre = float(np.linalg.norm(100.0 * (f.x[:n] - truth) / truth))
            bound = float(np.linalg.norm(100.0 * ci[:n] / Z95 / truth))
        vJ, _ = self.validation_J(f.names, f.x)
        return ModelReport(tuple(effs), f.names, f.x, ci, f.J, f.J, vJ, nre, None, fixed=f.fixed,
                           nre_bound_percent=bound)  # fmt: skip


def held_out(system: LumpedSystem, ref: tuple) -> NDArray:
    """(R,) True on the residual entries of the held-out blocks of every run."""
    return np.concatenate([holdout_blocks(rig.t.size)[o.sample_times()]
                           for rig, o in zip(system.rigs, system.objectives(ref), strict=True)])  # fmt: skip


def quality_of(system: LumpedSystem, ref: tuple, before: ModelReport) -> Quality:
    """Can the data tell: enough samples, the noise below half the signal, the declared unknowns determined."""
    samples = sum(rig.t.size for rig in system.rigs)
    ratios = [np.asarray(w[f]) / np.maximum(np.std(r[f], axis=0), 1e-300)
              for w, r in zip(system.weights, ref, strict=True) for f in r]  # fmt: skip
    noise = float(np.median(np.concatenate(ratios)))
    reasons = []
    if samples < MIN_SAMPLES:
        reasons.append(f"too short: {samples} samples per channel, at least {MIN_SAMPLES} needed")
    if not noise <= MAX_NOISE_RATIO:
        reasons.append(f"too noisy: the noise is {100 * noise:.0f} % of the signal")
    n = len(system.names)
    x, ci = before.x[:n], before.ci[:n]
    rel = np.where(np.abs(x) > 0, ci / np.maximum(np.abs(x), 1e-300), np.inf)
    loose = [name for name, r in zip(system.names, rel, strict=True) if not np.isfinite(r)]
    if loose:
        reasons.append(f"not excited enough to determine the declared model: {', '.join(loose)} undetermined")
    worst = float(np.max(rel)) if rel.size and np.all(np.isfinite(rel)) else None
    return Quality(tuple(reasons), samples, noise, worst)


def fit_declared(system: LumpedSystem, problem, refit_budget: int, say) -> Fit:
    """The declared model by the configured algorithm (run 0's optimizer stream), polished to the minimum."""
    ident = system.config.identify
    opt = get_optimizer(ident.algorithm.name, ident.algorithm.population, ident.algorithm.iterations)
    res = opt.minimize(problem, run_streams(ident.seed, 0).optimizer, budget=ident.budget, x0=system.box.nominal)
    fit = lsq_fit(problem, res.x, refit_budget)
    say(f"declared model: J = {fit.J:.4g} ({res.evaluations + fit.evaluations} evaluations)")
    return fit


def diagnose_rig(
    cls: type[LumpedSystem],
    config: LumpedConfig,
    files: Sequence[str],
    validate: Sequence[str] = (),
    log=None,
    *,
    alpha: float = ALPHA,
    max_rounds: int = MAX_ROUNDS,
    progress: ProgressHook | None = None,
) -> Diagnosis:
    """Close the loop on the measured runs `files` (jointly), judged on the `validate` runs (else held-out blocks);
    `progress` hears of each step (the declared fit, each candidate tested, each re-fit)."""
    t_start = time.perf_counter()
    say = log or (lambda _m: None)
    if not files:
        raise InputError("diagnose needs --data FILE (the measured run to fit) or data.files", source=config.source)
    system = cls(config, DataSource(tuple(map(str, files))))
    system.kernel = True  # every fit by one scheme, with effects or without
    ref = system.reference(0)
    if validate:
        other = cls(config, DataSource(tuple(map(str, validate))))
        other.kernel = True
        keep, validation, source = None, (other, other.reference(0), None), "--validate " + " + ".join(validate)
    else:
        held = held_out(system, ref)
        keep, validation = ~held, (system, ref, held)
        source = f"held-out blocks of {' + '.join(files)} (every {HOLDOUT_EVERY}th block)"
    R_total = system.residual_samples
    R_train = int(R_total if keep is None else keep.sum())
    specs = {**rig_candidates(system), **parameter_specs(system)}
    rig = RigLoop(system, ref, keep, validation, specs)
    step = progress or (lambda _stage, _done, _total: None)
    step("declared fit", 0, 1)
    fit = fit_declared(system, rig.problem_for(system.names)[0], REFIT_BUDGET, say)
    before = rig.report(fit, ())
    step("declared fit", 1, 1)
    quality = quality_of(system, ref, before)
    subject = Subject(
        specs=specs, declared=frozenset(), problem_for=rig.problem_for, validation_J=rig.validation_J,
        residual_count=R_train, statistic=lambda _fit: chi2_statistic(R_train), scale=lambda f: f.J,
        noise_limit=chi2_limit(R_train),
    )  # fmt: skip
    return close(
        subject, fit, before, rig.report, quality, alpha=alpha, max_rounds=max_rounds,
        candidate_budget=CANDIDATE_BUDGET, refit_budget=REFIT_BUDGET, say=say, t_start=t_start,
        chi2_residuals=R_total, validation_source=source, sigma_source=system.sigma_source,
        validation_from_file=bool(validate), system=system.name,
        data_files=tuple(map(str, files)) if len(files) > 1 else (), unit=config.unit, progress=progress,
    )  # fmt: skip
