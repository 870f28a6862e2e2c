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
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from ..config import Config, config_from_dict
from ..experiment import run_streams
from ..identification import Task, build_task
from ..optimizers import get_optimizer
from ..optimizers.base import Problem
from .attribution import (
    ALPHA,
    CANDIDATE_BUDGET,
    Candidate,
    Fit,
    Ranked,
    candidate_ranges,
    candidate_specs,
    chi2_statistic,
    lsq_fit,
    rank_candidates,
    undistinguished,
)
from .quality import Quality, assess_vehicle
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
    """One model's fit: estimates with 95 % intervals, J, validation J, NRE."""

    effects: tuple[str, ...]
    names: tuple[str, ...]
    x: NDArray
    ci: NDArray  # (D,) half-width of the 95 % interval (NaN where the information is singular)
    J: float
    chi2_per_sample: float | None
    validation_J: float | None
    nre_percent: float | None
    analysis: ResidualAnalysis | None = None
    validation_per_file: dict[str, float] | None = None

    def to_json(self, validation_from_file: bool = True) -> dict:
        out = {
            "effects": list(self.effects),
            "estimates": {n: float(v) for n, v in zip(self.names, self.x, strict=True)},
            "ci95": {n: [float(v - h), float(v + h)] for n, v, h in zip(self.names, self.x, self.ci, strict=True)},
            "J": self.J,
            "chi2_per_sample": self.chi2_per_sample,
            "validation_J": self.validation_J if validation_from_file else None,
            "nre_percent": self.nre_percent,
            "residual": None if self.analysis is None else self.analysis.summary(),
        }
        if not validation_from_file:
            out["holdout_J"] = self.validation_J
        if self.validation_per_file:
            out["validation_J_per_file"] = dict(self.validation_per_file)
        return out


@dataclass(frozen=True)
class Step:
    """One effect the loop added: J on the training data and on the validation data, before and after."""

    effect: str
    J_before: float
    J_after: float
    validation_J_before: float
    validation_J_after: float
    validation_per_file_after: dict[str, float] | None = None

    def to_json(self) -> dict:
        out = {
            "effect": self.effect, "J_before": self.J_before, "J_after": self.J_after,
            "validation_J_before": self.validation_J_before, "validation_J_after": self.validation_J_after,
        }  # fmt: skip
        if self.validation_per_file_after:
            out["validation_J_per_file_after"] = dict(self.validation_per_file_after)
        return out


@dataclass(frozen=True)
class Diagnosis:
    """The loop's outcome: the declared and the final model, every round's ranking, what was added."""

    before: ModelReport
    after: ModelReport
    rounds: tuple[tuple[Ranked, ...], ...]
    selected: tuple[str, ...]
    alpha: float
    validation_source: str
    sigma_source: str
    wall_s: float
    notes: tuple[str, ...] = field(default_factory=tuple)
    steps: tuple[Step, ...] = ()
    quality: Quality = field(default_factory=Quality)
    system: str = "vehicle"
    J_definition: str = "wls: noise-weighted residual power per sample (chi2 per sample) on the training data"
    validation_from_file: bool = True

    @property
    def verdict(self) -> str:
        """One line: what the loop concluded."""
        if self.selected:
            found = "missing physics found: " + ", ".join(self.selected)
            ambiguous = [n for n in self.notes if n.startswith("cannot tell")]
            return found + (f" (then stopped: {ambiguous[0]})" if ambiguous else "")
        if not self.quality.ok:
            return "inconclusive, no effect claimed: " + "; ".join(self.quality.reasons)
        if any(n.startswith("cannot tell") for n in self.notes):
            return "inconclusive, no effect claimed: " + next(n for n in self.notes if n.startswith("cannot tell"))
        return "nothing missing: no candidate is significant and improves the validation fit"

    def to_json(self) -> dict:
        vf = self.validation_from_file
        return {
            "system": self.system,
            "J_definition": self.J_definition,
            "before": self.before.to_json(vf),
            "after": self.after.to_json(vf),
            "candidates": [r.to_json() for r in self.rounds[0]] if self.rounds else [],
            "rounds": [[r.to_json() for r in rnd] for rnd in self.rounds],
            "selected": list(self.selected),
            "steps": [s.to_json() for s in self.steps],
            "verdict": self.verdict,
            "data_quality": self.quality.to_json(),
            "alpha": self.alpha,
            "validation": self.validation_source,
            "noise": self.sigma_source,
            "wall_s": self.wall_s,
            "notes": list(self.notes),
        }


@dataclass(frozen=True)
class Subject:
    """What the loop needs of the system under diagnosis (the car or a damper on a bench).

    problem_for(names): the training problem over the unknowns `names` (declared first, then effect
    parameters) and a start value for each; validation_J(names, x): J on the validation data, and per file;
    statistic(current): the LR function (J_before, J_with) -> statistic for tests against the fit `current`.
    """

    specs: dict[str, Candidate]
    declared: frozenset[str]
    problem_for: Callable[[tuple[str, ...]], tuple[Problem, NDArray]]
    validation_J: Callable[[tuple[str, ...], NDArray], tuple[float, dict[str, float] | None]]
    residual_count: int
    statistic: Callable[[Fit], Callable[[float, float], float]]
    min_gain: float = 0.0


@dataclass(frozen=True)
class Loop:
    """The augmentation loop's end state."""

    fit: Fit
    effects: tuple[str, ...]
    rounds: tuple[tuple[Ranked, ...], ...]
    steps: tuple[Step, ...]
    notes: tuple[str, ...] = ()


def augment(
    subject: Subject,
    fit: Fit,
    *,
    alpha: float,
    max_rounds: int,
    candidate_budget: int,
    refit_budget: int,
    claim: bool = True,
    say: Callable[[str], None] = lambda _m: None,
) -> Loop:
    """Rank the candidates against `fit`, add the best accepted one, re-fit everything (its shape parameters
    freed too), repeat until none is accepted or max_rounds; with claim=False only rank once."""
    specs = subject.specs
    effects: list[str] = []
    rounds: list[tuple[Ranked, ...]] = []
    steps: list[Step] = []
    notes: list[str] = []
    dropped: set[str] = set()
    current = fit
    current_vJ, _ = subject.validation_J(fit.names, fit.x)

    def make_problem(names: tuple[str, ...], cand: Candidate):
        new = tuple(n for n in cand.unknowns if n not in names)
        problem, start = subject.problem_for(names + new)
        return problem, start[len(names) :]

    def vJ(names, x) -> float:
        return subject.validation_J(names, x)[0]

    for _ in range(max_rounds if claim else 1):
        todo = [specs[e] for e in specs if e not in subject.declared and e not in effects and e not in dropped]
        if not todo:
            break
        ranked = rank_candidates(
            todo, current, current_vJ, make_problem, vJ, subject.residual_count, alpha, candidate_budget,
            statistic=subject.statistic(current), min_gain=subject.min_gain, claim=claim,
        )  # fmt: skip
        rounds.append(tuple(ranked))
        say("candidates: " + ", ".join(f"{r.effect} LR={r.statistic:.3g}" for r in ranked))
        best = next((r for r in ranked if r.accepted), None)
        if best is None:
            break
        rival = undistinguished(ranked, best, alpha)
        if rival is not None:
            notes.append(
                f"cannot tell {best.effect} (LR {best.statistic:.3g}) from {rival.effect} (LR {rival.statistic:.3g}) "
                "apart on these data: neither added"
            )
            say(notes[-1])
            break
        effects.append(best.effect)
        names = best.fit.names + tuple(n for n in specs[best.effect].shape if n not in best.fit.names)
        problem, start = subject.problem_for(names)
        x0 = np.concatenate([best.fit.x, start[len(best.fit.names) :]])
        refit = lsq_fit(problem, x0, refit_budget)
        if refit.J > best.fit.J:  # keep the short fit if the re-fit found nothing better
            refit = Fit(names, x0, best.fit.J, refit.evaluations)
        # backward check: with everything re-fitted, is the effect still needed? (a short fit without it)
        added = [n for n in names if n not in current.names]
        own = [n for n in added if "." in n] or added  # its own parameters, not the car's it also freed
        reduced = tuple(n for n in names if n not in own)
        problem_r, _ = subject.problem_for(reduced)
        without = lsq_fit(problem_r, refit.x[[names.index(n) for n in reduced]], candidate_budget)
        J_without = min(without.J, current.J)
        p_keep = float(stats.chi2.sf(subject.statistic(refit)(J_without, refit.J), len(own)))
        if p_keep >= alpha / len(todo):
            effects.pop()
            dropped.add(best.effect)
            notes.append(
                f"{best.effect} dropped after the re-fit: without it J = {J_without:.4g} against {refit.J:.4g} "
                f"(p = {p_keep:.2g}); its gain was the other parameters converging"
            )
            say(notes[-1])
            if without.J < current.J:
                current = without
                current_vJ, _ = subject.validation_J(current.names, current.x)
            continue
        for n in own:  # an estimate on its search bound: say so (the effect may stand for something else)
            j = names.index(n)
            lo, hi = problem.lower[j], problem.upper[j]
            if min(refit.x[j] - lo, hi - refit.x[j]) <= 1e-6 * (hi - lo):
                notes.append(f"{n} = {refit.x[j]:.4g} sits on its search bound [{lo:.4g}, {hi:.4g}]")
        new_vJ, per_file = subject.validation_J(refit.names, refit.x)
        steps.append(Step(best.effect, current.J, refit.J, current_vJ, new_vJ, per_file))
        current, current_vJ = refit, new_vJ
        say(f"added {best.effect}: J = {current.J:.4g}, validation J = {current_vJ:.4g}")
    return Loop(current, tuple(effects), tuple(rounds), tuple(steps), tuple(notes))


def block_size(n: int) -> int:
    """Samples per hold-out block: BLOCK, smaller on short data so that every run has held-out blocks."""
    return max(1, min(BLOCK, n // (2 * HOLDOUT_EVERY)))


def holdout_blocks(n: int) -> NDArray:
    """(n,) True on the held-out samples: every HOLDOUT_EVERY-th block of block_size(n)."""
    return (np.arange(n) // block_size(n)) % HOLDOUT_EVERY == HOLDOUT_EVERY - 1


def masked(problem: Problem, keep: NDArray | None) -> Problem:
    """The problem on the kept residuals only (cost: their chi² per sample); diverging candidates (NaN, inf)
    are the optimizer's to penalise, without floating-point warnings."""

    def cr(X):
        with np.errstate(all="ignore"):
            _, r = problem.residuals(X)
            r = r if keep is None else r[:, keep]
            return np.mean(r**2, axis=1), r

    return Problem(problem.lower, problem.upper, lambda X: cr(X)[0], cr, problem.penalty, problem.names)


def fisher_ci(problem: Problem, x: NDArray, scale: float) -> NDArray:
    """95 % half-widths from (J'J)^-1 scale at x, J the Jacobian of the problem's residuals (forward
    differences, one batch) and `scale` the variance of one residual entry."""
    width = problem.upper - problem.lower
    h = 1e-6 * np.maximum(np.abs(x), 1e-3 * width)
    step = np.where(x + h <= problem.upper, h, -h)
    X = np.vstack([x[None, :], x[None, :] + np.diag(step)])
    _, R = problem.residuals(X)
    Jac = ((R[1:] - R[0][None, :]) / step[:, None]).T
    try:
        cov = np.linalg.inv(Jac.T @ Jac) * max(scale, 1e-300)
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
        held = holdout_blocks(n)
        per_sample = np.tile(np.repeat(held, 4), len(task.families))  # residual layout: family, time, channel
        keep, vkeep = ~per_sample, per_sample
        vsource = f"held-out blocks of {data_file} (every {HOLDOUT_EVERY}th block of {block_size(n)} samples)"
    R_train = int(R_total if keep is None else keep.sum())

    def problem_of(t: Task, reference, mask) -> Problem:
        return masked(t.problem(reference), mask)

    def augmented(t: Task, names: tuple[str, ...], extra_task: dict) -> Task:
        """`t` with the unknowns `names` (the task's own first), their ranges from the candidates' specs."""
        extra = [n for n in names if n not in t.names]
        return t.with_unknowns(extra, limits=extra_task["limits"], start=extra_task["start"]) if extra else t

    specs = candidate_specs(config)
    declared = set(config.vehicle.effect_values())
    limits, starts = candidate_ranges(specs)
    ranges = {"limits": limits, "start": starts}

    def validation_J(names: tuple[str, ...], x: NDArray) -> tuple[float, None]:
        vt = augmented(vtask, names, ranges)
        cost = problem_of(vt, vref, vkeep).cost(np.asarray(x, dtype=float)[None, :])[0]
        return (float(cost) if np.isfinite(cost) else float("inf")), None

    def problem_for(names: tuple[str, ...]) -> tuple[Problem, NDArray]:
        t = augmented(task, names, ranges)
        return problem_of(t, ref, keep), t.nominal

    # 1. the declared model, by the configured algorithm (the campaign's run 0 streams)
    ident = config.identify
    base_problem = problem_of(task, ref, keep)
    opt = get_optimizer(ident.algorithm.name, ident.algorithm.population, ident.algorithm.iterations)
    x0 = task.nominal if ident.start == "nominal" else None
    res = opt.minimize(base_problem, run_streams(ident.seed, 0).optimizer, budget=ident.budget, x0=x0)
    fit = lsq_fit(base_problem, res.x, refit_budget)  # polish to the likelihood's minimum
    say(f"declared model: J = {fit.J:.4g} ({res.evaluations + fit.evaluations} evaluations)")

    def report(f: Fit, effs) -> ModelReport:
        t = augmented(task, f.names, ranges)
        ci = fisher_ci(problem_of(t, ref, keep), f.x, f.J)
        nre = None
        if task.truth is not None:
            idx = [f.names.index(n) for n in task.names]
            nre = float(np.linalg.norm(100.0 * (f.x[idx] - task.truth) / task.truth))
        vJ, _ = validation_J(f.names, f.x)
        an = analyse(t, ref, f.names, f.x) if analyse_residuals else None
        chi2 = an.chi2_per_sample if an is not None else f.J
        return ModelReport(tuple(effs), f.names, f.x, ci, f.J, chi2, vJ, nre, an)

    before = report(fit, ())
    quality = assess_vehicle(task, ref, before)
    subject = Subject(
        specs=specs, declared=frozenset(declared), problem_for=problem_for, validation_J=validation_J,
        residual_count=R_train, statistic=lambda _fit: chi2_statistic(R_train),
    )  # fmt: skip
    return close(
        subject, fit, before, report, quality, alpha=alpha, max_rounds=max_rounds, candidate_budget=candidate_budget,
        refit_budget=refit_budget, say=say, t_start=t_start, validation_source=vsource,
        sigma_source=task.sigma_source, validation_from_file=validate_file is not None,
    )  # fmt: skip


def close(
    subject: Subject,
    fit: Fit,
    before: ModelReport,
    report: Callable[[Fit, tuple[str, ...]], ModelReport],
    quality: Quality,
    *,
    alpha: float,
    max_rounds: int,
    candidate_budget: int,
    refit_budget: int,
    say: Callable[[str], None],
    t_start: float,
    **fields,
) -> Diagnosis:
    """Run the loop from the declared fit (no claims when the data fail `quality`) and report the outcome;
    `fields` are the Diagnosis's descriptive fields (validation and noise sources, system, J definition)."""
    loop = augment(
        subject, fit, alpha=alpha, max_rounds=max_rounds, candidate_budget=candidate_budget,
        refit_budget=refit_budget, claim=quality.ok, say=say,
    )  # fmt: skip
    return Diagnosis(
        before=before,
        after=report(loop.fit, loop.effects) if loop.effects else before,
        rounds=loop.rounds,
        selected=loop.effects,
        alpha=alpha,
        wall_s=time.perf_counter() - t_start,
        steps=loop.steps,
        quality=quality,
        notes=loop.notes,
        **fields,
    )
