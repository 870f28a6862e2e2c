"""The augmentation loop: fit the declared model, rank the candidates (missing effects and mis-set known
parameters), add the best accepted one, re-fit everything, repeat until none is accepted (at most MAX_ROUNDS);
then say honestly whether the residual is now at the noise.

J of the car is the wls objective, the noise-weighted residual power per sample (chi² per sample), on the
training data; the validation J is the same on the --validate run (its own noise sigma, the parameters
carried over unchanged: same car, another road), else on held-out blocks of the data (every HOLDOUT_EVERY-th
block of BLOCK samples is kept out of every fit, holdout.py). Confidence intervals: 95 %, from the Fisher information
J'J of the weighted residuals at the fit, scaled by the chi² per sample (the residual's own variance).

What is claimed: a candidate the likelihood-ratio test accepts (attribution.py), preferred over an effect
when it is a known parameter explaining the residual as well (parsimony), whose strength interval excludes
its null (zero, or the configured value) after the re-fit, and which is still needed once everything else is
re-fitted (backward checks after each round and at the end). The verdict compares the final residual power
with the noise: above 1 + 5 sqrt(2/R) (R residuals) it is ``incomplete``, whatever was found.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from ..core.result import Result
from ..optimizers.base import Problem
from .attribution import (
    PARAMETER_PREFIX,
    Candidate,
    Fit,
    Ranked,
    fisher_ci,
    fit_free,
    fit_intervals,
    identifiable,
    lowers_validation,
    parsimonious,
    rank_candidates,
    undistinguished,
)
from .bench_law import BenchLaw
from .quality import Quality
from .residuals import ResidualAnalysis
from .uncertainty import ModelUncertainty, compare_reports
from .unexplained import Unexplained

MAX_ROUNDS = 4
REFIT_BUDGET = 600


def chi2_limit(residual_count: int) -> float:
    """The largest residual power per sample (over the noise power) that is still noise: 1 + 5 sqrt(2/R)."""
    return 1.0 + 5.0 * math.sqrt(2.0 / max(residual_count, 1))


@dataclass(frozen=True)
class ModelReport(Result):
    """One model's fit: estimates with 95 % intervals (NaN: held fixed or undetermined), J, validation J, NRE."""

    effects: tuple[str, ...]
    names: tuple[str, ...]
    x: NDArray
    ci: NDArray  # (D,) half-width of the 95 % interval (NaN where the information is singular or x is fixed)
    J: float
    chi2_per_sample: float | None
    validation_J: float | None
    nre_percent: float | None
    analysis: ResidualAnalysis | None = None
    validation_per_file: dict[str, float] | None = None
    fixed: tuple[str, ...] = ()  # shape parameters the data could not tell, held at their start value
    nre_bound_percent: float | None = None  # the NRE's Cramér–Rao bound for this model (RSS of relative sds)
    run_analyses: tuple[tuple[str, ResidualAnalysis], ...] = ()  # several runs: (file, its analysis) each
    ci_misfit: NDArray | None = None  # residual above the noise: 95 % half-widths that survive the misfit (sandwich)

    def to_json(self, validation_from_file: bool = True) -> dict:
        def ci(v, h):
            return [float(v - h), float(v + h)] if np.isfinite(h) else None

        out = {
            "effects": list(self.effects),
            "estimates": {n: float(v) for n, v in zip(self.names, self.x, strict=True)},
            "ci95": {n: ci(v, h) for n, v, h in zip(self.names, self.x, self.ci, strict=True)},
            "fixed": list(self.fixed),
            "J": self.J,
            "chi2_per_sample": self.chi2_per_sample,
            "validation_J": self.validation_J if validation_from_file else None,
            "nre_percent": self.nre_percent,
            "nre_bound_percent": self.nre_bound_percent,
            "residual": None if self.analysis is None else self.analysis.summary(),
        }
        if self.ci_misfit is not None:  # marked: intervals that account for the misfit, beside those that assume none
            out["ci95_misfit"] = {n: ci(v, h) for n, v, h in zip(self.names, self.x, self.ci_misfit, strict=True)}
            out["ci95_misfit_method"] = "sandwich over 30 stretches of the record (the residual's correlation kept)"
        if not validation_from_file:
            out["holdout_J"] = self.validation_J
        if self.validation_per_file:
            out["validation_J_per_file"] = dict(self.validation_per_file)
        if self.run_analyses:
            out["residual_per_file"] = {f: a.summary() for f, a in self.run_analyses}
        return out


@dataclass(frozen=True)
class Step(Result):
    """One candidate the loop added: J on the training data and on the validation data, before and after."""

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
class Diagnosis(Result):
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
    chi2_limit: float | None = None  # residual power per sample above which the residual is not noise
    unexplained: Unexplained | BenchLaw | None = None  # the non-parametric force left unexplained (incomplete)
    data_files: tuple[str, ...] = ()  # several runs fitted jointly (empty: one run)
    checks: tuple[dict, ...] = ()  # the pre-fit checks of the measurement chain (SPEC section 6)
    model_uncertainty: ModelUncertainty | None = None  # the selected terms against the non-parametric explanation

    @property
    def imitation(self) -> bool:
        """Do the selected library terms only imitate a law they do not contain (uncertainty.py)?"""
        return bool(self.model_uncertainty is not None and self.model_uncertainty.imitates)

    @property
    def residual_ratio(self) -> float | None:
        """The final residual power over the noise power (chi² per sample)."""
        return self.after.chi2_per_sample

    @property
    def at_noise(self) -> bool | None:
        """Is the final residual at the noise (None where the noise is unknown)?"""
        r = self.residual_ratio
        if r is None or self.chi2_limit is None or not np.isfinite(r):
            return None
        return bool(r <= self.chi2_limit)

    @property
    def verdict(self) -> str:
        """One line whose first word is adequate, found, incomplete or inconclusive (SPEC section 5)."""
        ambiguous = next((n for n in self.notes if n.startswith("cannot tell")), None)
        if not self.quality.ok:
            return "inconclusive, no effect claimed: " + "; ".join(self.quality.reasons)
        if ambiguous and not self.selected:
            return "inconclusive, no effect claimed: " + ambiguous
        found = ", ".join(self.selected)
        level = "" if self.at_noise is None else f" (residual {self.residual_ratio:.3g}x the noise)"
        if self.imitation and self.at_noise is not False:
            out = "incomplete: library terms imitate a law they do not contain: " + self.model_uncertainty.summary()
            law = self.unexplained is not None and self.unexplained.significant
            return out + (f"; the unexplained strut force {self.unexplained.summary()}" if law else "") + level
        if self.at_noise is False:
            out = f"incomplete: residual {self.residual_ratio:.3g}x the noise (noise: at most {self.chi2_limit:.3g}x)"
            none = "; no library effect or known parameter explains it"
            out += f"; the library's best approximation adds {found} but does not explain it" if found else none
            if self.imitation:
                out += "; library terms imitate a law they do not contain: " + self.model_uncertainty.summary()
            if self.unexplained is not None and self.unexplained.significant:
                noun = getattr(self.unexplained, "noun", "strut force")
                out += f"; the unexplained {noun} {self.unexplained.summary()}"
            return out + (f" (then stopped: {ambiguous})" if ambiguous else "")
        if self.selected:
            return f"found: {found}; the residual is now at the noise{level}"
        return f"adequate: nothing missing, the residual is at the noise{level}"

    def to_json(self) -> dict:
        vf = self.validation_from_file
        after = self.after.to_json(vf)
        if self.imitation:  # the intervals that cover the model uncertainty, beside those that assume the model
            after["ci95_model_uncertainty"] = self.model_uncertainty.to_json()["ci95_model_uncertainty"]
        return {
            "system": self.system,
            "J_definition": self.J_definition,
            "before": self.before.to_json(vf),
            "after": after,
            "candidates": [r.to_json() for r in self.rounds[0]] if self.rounds else [],
            "rounds": [[r.to_json() for r in rnd] for rnd in self.rounds],
            "selected": list(self.selected),
            "steps": [s.to_json() for s in self.steps],
            "verdict": self.verdict,
            "chi2_limit": self.chi2_limit,
            "unexplained": None if self.unexplained is None else self.unexplained.to_json(),
            "data_quality": self.quality.to_json(),
            "alpha": self.alpha,
            "validation": self.validation_source,
            "noise": self.sigma_source,
            "wall_s": self.wall_s,
            "notes": list(self.notes),
            "checks": [dict(c) for c in self.checks],
            "model_uncertainty": None if self.model_uncertainty is None else self.model_uncertainty.to_json(),
        } | ({"data_files": list(self.data_files)} if self.data_files else {})


@dataclass(frozen=True)
class Subject:
    """What the loop needs of the system under diagnosis (the car or a damper on a bench).

    problem_for(names): the training problem over the unknowns `names` (declared first, then candidates'
    parameters) and a start value for each; validation_J(names, x): J on the validation data, and per file;
    statistic(current): the LR function (J_before, J_with) -> statistic for tests against the fit `current`;
    scale(fit): the variance of one training residual entry at a fit (for intervals).
    """

    specs: dict[str, Candidate]
    declared: frozenset[str]
    problem_for: Callable[[tuple[str, ...]], tuple[Problem, NDArray]]
    validation_J: Callable[[tuple[str, ...], NDArray], tuple[float, dict[str, float] | None]]
    residual_count: int
    statistic: Callable[[Fit], Callable[[float, float], float]]
    scale: Callable[[Fit], float]
    min_gain: float = 0.0
    noise_limit: float | None = None  # training J at or below which the residual is noise (None: J is not chi²)

    def intervals(self, fit: Fit) -> NDArray:
        """95 % half-widths at a fit over its free unknowns (NaN for the fixed ones)."""
        return fit_intervals(self.problem_for(fit.names)[0], fit, self.scale(fit))


@dataclass(frozen=True)
class Loop:
    """The augmentation loop's end state."""

    fit: Fit
    effects: tuple[str, ...]
    rounds: tuple[tuple[Ranked, ...], ...]
    steps: tuple[Step, ...]
    notes: tuple[str, ...] = ()


def own_unknowns(cand: Candidate, names: tuple[str, ...]) -> list[str]:
    """A claimed candidate's own unknowns among `names`: an effect's parameters (not the car's it also
    freed), a known parameter itself."""
    if cand.kind in ("parameter", "sensor"):
        return [n for n in cand.unknowns if n in names]
    return [n for n in names if n.partition(".")[0] == cand.effect]


def strength_excludes_null(cand: Candidate, fit: Fit, ci: NDArray) -> list[str]:
    """The candidate's strength unknowns whose 95 % interval at the fit excludes their null value."""
    out = []
    for n in cand.strength:
        if n in fit.names:
            j = fit.names.index(n)
            if np.isfinite(ci[j]) and abs(fit.x[j] - cand.null.get(n, 0.0)) > ci[j]:
                out.append(n)
    return out


@dataclass
class _Augmentation:
    """The loop's running state: the current fit and its validation J, what is claimed, dropped and noted so far,
    every round's ranking and the steps taken; its methods are the loop's steps."""

    subject: Subject
    alpha: float
    candidate_budget: int
    refit_budget: int
    claim: bool
    say: Callable[[str], None]
    ordered: list[str]  # every candidate, those to fit first first
    current: Fit
    current_v: tuple[float, dict[str, float] | None]
    claimed: list[str] = field(default_factory=list)
    rounds: list[tuple[Ranked, ...]] = field(default_factory=list)
    steps: list[Step] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    dropped: set[str] = field(default_factory=set)

    def note(self, text: str) -> None:
        """Record a note and say it."""
        self.notes.append(text)
        self.say(text)

    def level(self, n: int) -> float:
        """The test level for one of n candidates (Bonferroni)."""
        return self.alpha / max(n, 1)

    def move_to(self, fit: Fit) -> None:
        """Make `fit` the current fit (its validation J computed)."""
        self.current = fit
        self.current_v = self.subject.validation_J(fit.names, fit.x)

    def make_problem(self, names: tuple[str, ...], cand: Candidate):
        """The problem over `names` plus the candidate's new unknowns, and the new unknowns' start values."""
        new = tuple(n for n in cand.unknowns + cand.shape if n not in names)
        problem, start = self.subject.problem_for(names + new)
        return problem, start[len(names) :]

    def removal_p(self, f: Fit, cand: Candidate, budget: int) -> tuple[float, Fit]:
        """p-value of keeping `cand` in the fit f: a short fit without its own unknowns, the LR test."""
        own = own_unknowns(cand, f.names)
        reduced = tuple(n for n in f.names if n not in own)
        problem_r, _ = self.subject.problem_for(reduced)
        idx = [f.names.index(n) for n in reduced]
        free = np.array([n not in f.fixed for n in reduced])
        without = fit_free(problem_r, f.x[idx], free, budget)
        k = cand.df if cand.df is not None else len([n for n in own if n not in f.fixed])
        return float(stats.chi2.sf(self.subject.statistic(f)(without.J, f.J), max(k, 1))), without

    def round(self) -> bool:
        """One round: rank the candidates against the current fit and try to add the best accepted one. False when
        the loop stops: the residual is at the noise, no candidate is left or accepted, or the data cannot tell the
        best from another."""
        subject, current = self.subject, self.current
        specs = subject.specs
        todo = [
            specs[e] for e in self.ordered
            if e not in subject.declared and e not in self.claimed and e not in self.dropped
            and not (specs[e].kind == "parameter" and specs[e].unknowns[0] in current.names)
        ]  # fmt: skip
        if self.claimed and subject.noise_limit is not None and current.J <= subject.noise_limit:
            # a second mis-set known parameter hardly shows in J at the noise but biases the unknowns: test those
            todo = [c for c in todo if c.kind == "parameter"]
            at = f"the residual is at the noise (J = {current.J:.4g} <= {subject.noise_limit:.4g})"
            self.note(f"{at}: only the known parameters are tested further" if todo else f"stopped: {at}")
            if not todo:
                return False
        if not todo:
            return False
        best = self.choose(self.rank(todo))
        if best is None:
            return False
        self.try_claim(best, len(todo))
        return True

    def rank(self, todo: list[Candidate]) -> list[Ranked]:
        """The candidates `todo` ranked against the current fit (the round recorded and said)."""
        subject, current = self.subject, self.current
        ranked = rank_candidates(
            todo, current, self.current_v, self.make_problem, subject.validation_J, subject.residual_count,
            self.alpha, self.candidate_budget, statistic=subject.statistic(current), min_gain=subject.min_gain,
            claim=self.claim, scale=subject.scale(current),
            prior={r.effect: r for r in self.rounds[-1]} if self.rounds else None,
        )  # fmt: skip
        self.rounds.append(tuple(ranked))
        self.say("candidates: " + ", ".join(f"{r.effect} LR={r.statistic:.3g}" for r in ranked))
        return ranked

    def choose(self, ranked: list[Ranked]) -> Ranked | None:
        """The best accepted candidate, a known parameter explaining the residual as well preferred; None when none
        is accepted or the data cannot tell it from another."""
        best = next((r for r in ranked if r.accepted), None)
        if best is None:
            return None
        simpler = parsimonious(ranked, best, self.alpha)
        if simpler is not None:
            self.note(
                f"{simpler.effect} explains the residual as well as {best.effect} (LR {simpler.statistic:.4g} "
                f"against {best.statistic:.4g}): the known parameter is preferred"
            )
            best = simpler
        rival = undistinguished(ranked, best, self.alpha)
        if rival is not None:
            self.note(
                f"cannot tell {best.effect} (LR {best.statistic:.3g}) from {rival.effect} (LR {rival.statistic:.3g}) "
                "apart on these data: neither added"
            )
            return None
        return best

    def refit(self, best: Ranked) -> tuple[Problem, tuple[str, ...], Fit]:
        """Re-fit everything from the candidate's fit, the identifiable shape parameters of every claim freed (the
        candidate's fit kept if the re-fit found nothing better): the problem, its unknowns and the fit."""
        specs, subject = self.subject.specs, self.subject
        cand = specs[best.effect]
        extra = tuple(n for n in cand.companions if n not in best.fit.names)
        names = best.fit.names + extra
        problem, start = subject.problem_for(names)
        x0 = np.concatenate([best.fit.x, start[len(best.fit.names) :]])
        shapes = [n for e in (*self.claimed, best.effect) for n in specs[e].shape]
        free = identifiable(names, x0, fisher_ci(problem, x0, subject.scale(best.fit)), shapes)
        refit = fit_free(problem, x0, free, self.refit_budget)
        if refit.J > best.fit.J:  # keep the candidate's fit if the re-fit found nothing better
            refit = Fit(names, x0, best.fit.J, refit.evaluations, best.fit.fixed)
        return problem, names, refit

    def try_claim(self, best: Ranked, candidates: int) -> None:
        """Re-fit with `best` (one of `candidates` tested) and claim it if its strength interval excludes its null,
        it is still needed after the re-fit and it lowers the validation J; else it is dropped."""
        cand = self.subject.specs[best.effect]
        problem, names, refit = self.refit(best)
        ci = self.subject.intervals(refit)
        if not strength_excludes_null(cand, refit, ci):
            shown = ", ".join(
                f"{n} = {refit.x[refit.names.index(n)]:.3g} ± {ci[refit.names.index(n)]:.2g}"
                for n in cand.strength if n in refit.names
            )  # fmt: skip
            what = {"parameter": "its configured value", "sensor": "its no-fault value"}.get(cand.kind, "zero")
            self.note(f"{best.effect} not claimed: its strength interval includes {what} ({shown})")
            self.dropped.add(best.effect)
            return
        p_keep, without = self.removal_p(refit, cand, self.candidate_budget)
        if p_keep >= self.level(candidates):
            self.dropped.add(best.effect)
            self.note(
                f"{best.effect} dropped after the re-fit: without it J = {without.J:.4g} against {refit.J:.4g} "
                f"(p = {p_keep:.2g}); its gain was the other parameters converging"
            )
            if without.J < self.current.J:
                self.move_to(without)
            return
        self.note_estimates(cand, problem, names, refit)
        new_v = self.subject.validation_J(refit.names, refit.x)
        if not lowers_validation(*new_v, *self.current_v, 0.0):
            runs = "" if not new_v[1] else " on every held-out run"
            self.note(f"{best.effect} not claimed: after the re-fit it does not lower the validation J{runs}")
            self.dropped.add(best.effect)
            return
        self.claimed.append(best.effect)
        self.steps.append(Step(best.effect, self.current.J, refit.J, self.current_v[0], new_v[0], new_v[1]))
        self.current, self.current_v = refit, new_v
        self.say(f"added {best.effect}: J = {self.current.J:.4g}, validation J = {self.current_v[0]:.4g}")

    def note_estimates(self, cand: Candidate, problem: Problem, names: tuple[str, ...], refit: Fit) -> None:
        """Note (silently) the candidate's estimates on their search bound and its shape parameters held fixed."""
        for n in own_unknowns(cand, names):  # an estimate on its search bound: say so
            j = names.index(n)
            lo, hi = problem.lower[j], problem.upper[j]
            if n not in refit.fixed and min(refit.x[j] - lo, hi - refit.x[j]) <= 1e-6 * (hi - lo):
                self.notes.append(f"{n} = {refit.x[j]:.4g} sits on its search bound [{lo:.4g}, {hi:.4g}]")
        for n in refit.fixed:
            if n in cand.shape:
                self.notes.append(
                    f"{n} held at {refit.x[names.index(n)]:.4g}: the data cannot tell it (Fisher information)"
                )

    def recheck_claims(self) -> None:
        """The final model: drop every claim no longer needed beside the others."""
        specs = self.subject.specs
        for e in list(self.claimed):
            p_keep, without = self.removal_p(self.current, specs[e], self.refit_budget)
            if p_keep >= self.level(len(specs)):
                self.claimed.remove(e)
                self.note(f"{e} dropped at the end: with the later claims it is no longer needed (p = {p_keep:.2g})")
                self.move_to(without)

    def polish(self) -> None:
        """The final model's joint least-squares polish of every free unknown from the loop's best point (kept when
        J falls): a re-fit that stopped short leaves the unknowns where a freed parameter's earlier value bent them."""
        f = self.current
        polished = fit_free(self.subject.problem_for(f.names)[0], f.x, [n not in f.fixed for n in f.names],
                            self.refit_budget)  # fmt: skip
        if polished.J < f.J:
            self.move_to(polished)

    def settle_companions(self, declared: int) -> None:
        """Known parameters an effect freed beside its own (asymmetric damping's cf, cr; unknowns after the first
        `declared`) whose effect was dropped: back to their configured value unless the data say they are off, then
        claimed as parameter:<name>."""
        specs = self.subject.specs
        companions = {n for e in self.claimed for n in specs[e].companions}
        for n in [n for n in self.current.names[declared:] if "." not in n and n not in companions]:
            name = PARAMETER_PREFIX + n
            if name in self.claimed or name not in specs:
                continue
            p_keep, without = self.removal_p(self.current, specs[name], self.refit_budget)
            ci = self.subject.intervals(self.current)
            if p_keep < self.level(len(specs)) and strength_excludes_null(specs[name], self.current, ci):
                self.claimed.append(name)
                self.notes.append(f"{n}, freed with a dropped effect, is off its configured value: claimed as {name}")
            else:
                self.move_to(without)
                self.notes.append(
                    f"{n}, freed with a dropped effect, is back at its configured value (p = {p_keep:.2g})"
                )
            self.say(self.notes[-1])


def augment(
    subject: Subject,
    fit: Fit,
    *,
    alpha: float,
    max_rounds: int,
    candidate_budget: int,
    refit_budget: int,
    claim: bool = True,
    order: tuple[str, ...] = (),
    say: Callable[[str], None] = lambda _m: None,
) -> Loop:
    """Rank the candidates against `fit`, add the best accepted one (a known parameter before an effect that
    explains no more), re-fit everything (identifiable shape parameters freed), keep it only if its strength
    interval excludes its null and it is still needed; repeat until none is accepted or max_rounds; then
    drop whatever the final model no longer needs. With claim=False only rank once. `order`: candidates to fit
    first (the non-parametric estimate's resemblance)."""
    specs = subject.specs
    run = _Augmentation(
        subject, alpha, candidate_budget, refit_budget, claim, say,
        ordered=[e for e in order if e in specs] + [e for e in specs if e not in order],
        current=fit, current_v=subject.validation_J(fit.names, fit.x),
    )  # fmt: skip
    for _ in range(max_rounds if claim else min(max_rounds, 1)):
        if not run.round():
            break
    if claim and len(run.claimed) > 1:  # the final model: is every claim still needed beside the others?
        run.recheck_claims()
    run.settle_companions(len(fit.names))
    if claim and run.claimed:
        run.polish()
    return Loop(run.current, tuple(run.claimed), tuple(run.rounds), tuple(run.steps), tuple(run.notes))


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
    chi2_residuals: int,
    order: tuple[str, ...] = (),
    unexplained: Unexplained | None = None,
    extra_notes: tuple[str, ...] = (),
    **fields,
) -> Diagnosis:
    """Run the loop from the declared fit (no claims when the data fail `quality`) and report the outcome;
    `chi2_residuals` is how many residuals the final chi² per sample averages (its noise limit);
    `unexplained`: the strut force the declared model misses, reported when the residual stays above the noise
    (against the declared model: what the library added did not explain it);
    `fields` are the Diagnosis's descriptive fields (validation and noise sources, system, J definition)."""
    rounds = max_rounds if quality.ok else (0 if quality.before_fit else 1)  # a failed pre-check: no fits at all
    loop = augment(
        subject, fit, alpha=alpha, max_rounds=rounds, candidate_budget=candidate_budget,
        refit_budget=refit_budget, claim=quality.ok, say=say, order=order,
    )  # fmt: skip
    after = report(loop.fit, loop.effects) if loop.fit is not fit else before
    limit = chi2_limit(chi2_residuals)
    incomplete = after.chi2_per_sample is not None and after.chi2_per_sample > limit
    uncertainty = compare_reports(loop.effects, before.names, after, unexplained) if quality.ok else None
    imitation = uncertainty is not None and uncertainty.imitates
    left = unexplained if quality.ok and (incomplete or imitation) else None
    return Diagnosis(
        before=before,
        after=after,
        rounds=loop.rounds,
        selected=loop.effects,
        alpha=alpha,
        wall_s=time.perf_counter() - t_start,
        steps=loop.steps,
        quality=quality,
        notes=loop.notes + extra_notes,
        chi2_limit=limit,
        unexplained=left,
        model_uncertainty=uncertainty,
        **fields,
    )
