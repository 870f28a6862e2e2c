"""The augmentation loop: fit the declared model, rank candidate effects, add the best accepted one,
re-fit everything (car and effect), repeat until no candidate is accepted (at most MAX_ROUNDS).

J of the car is the wls objective, the noise-weighted residual power per sample (chi² per sample), on the
training data; the validation J is the same on the --validate run (its own noise sigma, the parameters
carried over unchanged: same car, another road), else on held-out blocks of the data (every HOLDOUT_EVERY-th
block of BLOCK samples is kept out of every fit). Confidence intervals: 95 %, from the Fisher information
J'J of the weighted residuals at the fit, scaled by the chi² per sample (the residual's own variance).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..config import Config, config_from_dict
from ..experiment import run_streams
from ..identification import Task, build_task
from ..optimizers import get_optimizer
from ..optimizers.base import Problem
from .attribution import ALPHA, CANDIDATE_BUDGET, Candidate, Fit, Ranked, candidate_specs, lsq_fit, rank_candidates
from .residuals import ResidualAnalysis, analyse

MAX_ROUNDS = 3
REFIT_BUDGET = 600
BLOCK = 100  # samples per hold-out block
HOLDOUT_EVERY = 4  # without --validate, every 4th block is held out
Z95 = 1.959963984540054


def prepare_config(config: Config) -> Config:
    """The config the diagnosis runs on: wls objective, a time-stepping integrator (effects need one)."""
    raw = config.model_dump(mode="json", exclude_none=True)
    raw["identify"]["objective"] = "wls"
    if raw["simulation"].get("integrator") not in ("rk4", "newmark"):
        raw["simulation"]["integrator"] = "rk4"
    return config_from_dict(raw, config.source)


@dataclass(frozen=True)
class ModelReport:
    """One model's fit: estimates with 95 % intervals, J (= chi² per sample), validation J, NRE."""

    effects: tuple[str, ...]
    names: tuple[str, ...]
    x: NDArray
    ci: NDArray  # (D,) half-width of the 95 % interval (NaN where the information is singular)
    J: float
    chi2_per_sample: float
    validation_J: float | None
    nre_percent: float | None
    analysis: ResidualAnalysis | None = None

    def to_json(self) -> dict:
        return {
            "effects": list(self.effects),
            "estimates": {n: float(v) for n, v in zip(self.names, self.x, strict=True)},
            "ci95": {n: [float(v - h), float(v + h)] for n, v, h in zip(self.names, self.x, self.ci, strict=True)},
            "J": self.J,
            "chi2_per_sample": self.chi2_per_sample,
            "validation_J": self.validation_J,
            "nre_percent": self.nre_percent,
            "residual": None if self.analysis is None else self.analysis.summary(),
        }


@dataclass(frozen=True)
class Diagnosis:
    before: ModelReport
    after: ModelReport
    rounds: tuple[tuple[Ranked, ...], ...]
    selected: tuple[str, ...]
    alpha: float
    validation_source: str
    sigma_source: str
    wall_s: float
    notes: tuple[str, ...] = field(default_factory=tuple)

    def to_json(self) -> dict:
        return {
            "J_definition": "wls: noise-weighted residual power per sample (chi2 per sample) on the training data",
            "before": self.before.to_json(),
            "after": self.after.to_json(),
            "candidates": [r.to_json() for r in self.rounds[0]] if self.rounds else [],
            "rounds": [[r.to_json() for r in rnd] for rnd in self.rounds],
            "selected": list(self.selected),
            "alpha": self.alpha,
            "validation": self.validation_source,
            "noise": self.sigma_source,
            "wall_s": self.wall_s,
            "notes": list(self.notes),
        }


def _masked(problem: Problem, keep: NDArray | None) -> Problem:
    """The problem on the kept residuals only (cost: their chi² per sample); diverging candidates (NaN, inf)
    are the optimizer's to penalise, without floating-point warnings."""

    def cr(X):
        with np.errstate(all="ignore"):
            _, r = problem.residuals(X)
            r = r if keep is None else r[:, keep]
            return np.mean(r**2, axis=1), r

    return Problem(problem.lower, problem.upper, lambda X: cr(X)[0], cr, problem.penalty, problem.names)


def _fisher_ci(problem: Problem, x: NDArray, chi2: float) -> NDArray:
    """95 % half-widths from (J'J)^-1 chi2 at x (forward differences, one batch)."""
    width = problem.upper - problem.lower
    h = 1e-6 * np.maximum(np.abs(x), 1e-3 * width)
    step = np.where(x + h <= problem.upper, h, -h)
    X = np.vstack([x[None, :], x[None, :] + np.diag(step)])
    _, R = problem.residuals(X)
    Jac = ((R[1:] - R[0][None, :]) / step[:, None]).T
    try:
        cov = np.linalg.inv(Jac.T @ Jac) * max(chi2, 1e-12)
        return Z95 * np.sqrt(np.maximum(np.diag(cov), 0.0))
    except np.linalg.LinAlgError:
        return np.full(x.size, np.nan)


def diagnose(
    config: Config,
    data_file: str | Path,
    validate_file: str | Path | None = None,
    *,
    alpha: float = ALPHA,
    max_rounds: int = MAX_ROUNDS,
    candidate_budget: int = CANDIDATE_BUDGET,
    refit_budget: int = REFIT_BUDGET,
    analyse_residuals: bool = True,
    log=None,
) -> Diagnosis:
    """Close the loop on measured data `data_file` (see the module doc)."""
    t_start = time.perf_counter()
    say = log or (lambda _msg: None)
    config = prepare_config(config)
    task = build_task(config, data_file)
    ref = task.reference(0)
    R_total = task.residual_samples
    if validate_file is not None:
        vtask = build_task(config, validate_file)
        vref = vtask.reference(0)
        keep = vkeep = None
        vsource = f"--validate {validate_file}"
    else:
        vtask, vref = task, ref
        n = task.experiment.t.size
        held = (np.arange(n) // BLOCK) % HOLDOUT_EVERY == HOLDOUT_EVERY - 1
        per_sample = np.tile(np.repeat(held, 4), len(task.families))  # residual layout: family, time, channel
        keep, vkeep = ~per_sample, per_sample
        vsource = f"held-out blocks of {data_file} (every {HOLDOUT_EVERY}th block of {BLOCK} samples)"
    R_train = int(R_total if keep is None else keep.sum())

    def problem_of(t: Task, reference, mask) -> Problem:
        return _masked(t.problem(reference), mask)

    def augmented(t: Task, names: tuple[str, ...], extra_task: dict) -> Task:
        """`t` with the unknowns `names` (the task's own first), their ranges from the candidates' specs."""
        extra = [n for n in names if n not in t.names]
        return t.with_unknowns(extra, limits=extra_task["limits"], start=extra_task["start"]) if extra else t

    specs = candidate_specs(config)
    declared = set(config.vehicle.effect_values())
    ranges: dict = {"limits": {}, "start": {}}
    for c in specs.values():
        ranges["limits"].update(c.limits)
        ranges["limits"].update(c.shape_limits)
        ranges["start"].update(c.start)

    def validation_J(names: tuple[str, ...], x: NDArray) -> float:
        vt = augmented(vtask, names, ranges)
        cost = problem_of(vt, vref, vkeep).cost(np.asarray(x, dtype=float)[None, :])[0]
        return float(cost) if np.isfinite(cost) else float("inf")

    # 1. the declared model, by the configured algorithm (the campaign's run 0 streams)
    ident = config.identify
    base_problem = problem_of(task, ref, keep)
    opt = get_optimizer(ident.algorithm.name, ident.algorithm.population, ident.algorithm.iterations)
    x0 = task.nominal if ident.start == "nominal" else None
    res = opt.minimize(base_problem, run_streams(ident.seed, 0).optimizer, budget=ident.budget, x0=x0)
    fit = lsq_fit(base_problem, res.x, refit_budget)  # polish to the likelihood's minimum
    effects: list[str] = []
    say(f"declared model: J = {fit.J:.4g} ({res.evaluations + fit.evaluations} evaluations)")

    def report(f: Fit, effs) -> ModelReport:
        t = augmented(task, f.names, ranges)
        p = problem_of(t, ref, keep)
        ci = _fisher_ci(p, f.x, f.J)
        nre = None
        if task.truth is not None:
            idx = [f.names.index(n) for n in task.names]
            nre = float(np.linalg.norm(100.0 * (f.x[idx] - task.truth) / task.truth))
        vJ = validation_J(f.names, f.x)
        an = analyse(t, ref, f.names, f.x) if analyse_residuals else None
        chi2 = an.chi2_per_sample if an is not None else f.J
        return ModelReport(tuple(effs), f.names, f.x, ci, f.J, chi2, vJ, nre, an)

    before = report(fit, effects)
    rounds: list[tuple[Ranked, ...]] = []
    current, current_vJ = fit, before.validation_J

    def make_problem(names: tuple[str, ...], cand: Candidate):
        new = tuple(n for n in cand.unknowns if n not in names)
        t = augmented(task, names + new, ranges)
        return problem_of(t, ref, keep), t.nominal[len(names) :]

    for _ in range(max_rounds):
        todo = [specs[e] for e in specs if e not in declared and e not in effects]
        if not todo:
            break
        ranked = rank_candidates(
            todo, current, current_vJ, make_problem, validation_J, R_train, alpha, candidate_budget
        )
        rounds.append(tuple(ranked))
        say("candidates: " + ", ".join(f"{r.effect} LR={r.statistic:.3g}" for r in ranked))
        best = next((r for r in ranked if r.accepted), None)
        if best is None:
            break
        effects.append(best.effect)
        # re-fit everything, the selected effects' shape parameters freed too
        names = best.fit.names + tuple(n for n in specs[best.effect].shape if n not in best.fit.names)
        t = augmented(task, names, ranges)
        x0 = np.concatenate([best.fit.x, t.nominal[len(best.fit.names) :]])
        current = lsq_fit(problem_of(t, ref, keep), x0, refit_budget)
        current_vJ = validation_J(current.names, current.x)
        say(f"added {best.effect}: J = {current.J:.4g}, validation J = {current_vJ:.4g}")
    after = report(current, effects) if effects else before
    return Diagnosis(
        before=before,
        after=after,
        rounds=tuple(rounds),
        selected=tuple(effects),
        alpha=alpha,
        validation_source=vsource,
        sigma_source=task.sigma_source,
        wall_s=time.perf_counter() - t_start,
    )
