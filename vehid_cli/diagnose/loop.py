"""The augmentation loop: fit the declared model, rank the candidates (missing effects and mis-set known
parameters), add the best accepted one, re-fit everything, repeat until none is accepted (at most MAX_ROUNDS);
then say honestly whether the residual is now at the noise.

J of the car is the wls objective, the noise-weighted residual power per sample (chi² per sample), on the
training data; the validation J is the same on the --validate run (its own noise sigma, the parameters
carried over unchanged: same car, another road), else on held-out blocks of the data (every HOLDOUT_EVERY-th
block of BLOCK samples is kept out of every fit, holdout.py). Confidence intervals: 95 %, from the Fisher information
J'J of the weighted residuals at the fit, scaled by the chi² per sample (the residual's own variance).

What is claimed: a candidate the likelihood-ratio test accepts (attribution.py), preferred over an effect
when it is a known parameter explaining the residual as well, alone or with a second (parsimony), whose strength
interval excludes its null (zero, or the configured value) after the re-fit, and which is still needed once
everything else is re-fitted (backward checks after each round and at the end). The verdict compares the final
residual power with the noise: above 1 + 5 sqrt(2/R) (R residuals) it is ``incomplete``, whatever was found.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..core.progress import ProgressHook
from ..optimizers.base import Problem, forward_jacobian
from .attribution import (
    BEATERS,
    PARAMETER_PREFIX,
    SCORE_SKIP,
    Candidate,
    Fit,
    Ranked,
    fisher_ci,
    fit_free,
    identifiable,
    lowers_validation,
    parsimonious,
    rank_candidates,
    score_statistics,
    screenable,
    undistinguished,
)
from .claims import Removal, own_unknowns, pair_test, rival, strength_excludes_null, swap_test
from .quality import Quality
from .result import Diagnosis, ModelReport, Step, chi2_limit
from .score import Scores, cannot_win, fitted_basis, screen_effects
from .stops import STOP_FACTOR, STOP_STEPS
from .subject import Subject
from .tails import chi2_isf, chi2_sf
from .uncertainty import compare_reports
from .unexplained import Unexplained

MAX_ROUNDS = 4
REFIT_BUDGET = 600


@dataclass(frozen=True)
class Loop:
    """The augmentation loop's end state."""

    fit: Fit
    effects: tuple[str, ...]
    rounds: tuple[tuple[Ranked, ...], ...]
    steps: tuple[Step, ...]
    notes: tuple[str, ...] = ()


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
    current: Fit
    current_v: tuple[float, dict[str, float] | None]
    claimed: list[str] = field(default_factory=list)
    rounds: list[tuple[Ranked, ...]] = field(default_factory=list)
    steps: list[Step] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    dropped: set[str] = field(default_factory=set)
    progress: ProgressHook = field(default=lambda _stage, _done, _total: None)  # the steps, for a bar or log lines
    removals: dict[str, Removal] = field(default_factory=dict)  # effect: its last removal test

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

    def make_problem(self, names: tuple[str, ...], cand: Candidate, on: Subject | None = None):
        """The problem over `names` plus the candidate's new unknowns (on the subject `on`, default the loop's),
        and the new unknowns' start values."""
        new = tuple(n for n in cand.unknowns + cand.shape if n not in names)
        problem, start = (on or self.subject).problem_for(names + new)
        return problem, start[len(names) :]

    def make_linear(self, names: tuple[str, ...], cand: Candidate, on: Subject | None = None) -> Problem | None:
        """make_problem's problem on the exact integrator with its exact sensitivities (None: not the linear car)."""
        subject = on or self.subject
        if subject.linear_for is None:
            return None
        return subject.linear_for(names + tuple(n for n in cand.unknowns + cand.shape if n not in names))

    def removal_p(self, f: Fit, cand: Candidate, budget: int) -> tuple[float, Fit]:
        """p-value of keeping `cand` in f: a short fit without its own unknowns, the LR test. f's earlier test (the last
        claim's, again at the end) is reused if it stopped short of both budgets (a long record's began nearer)."""
        done = self.removals.get(cand.effect)
        if done is not None and done.fit is f and done.without.evaluations + 1 < min(budget, done.budget):
            return done.p, done.without
        own = own_unknowns(cand, f.names)
        reduced = tuple(n for n in f.names if n not in own)
        idx = [f.names.index(n) for n in reduced]
        free = np.array([n not in f.fixed for n in reduced])
        start = f.x[idx]
        now = self.current
        same = now.names == reduced and set(now.fixed) == {n for n in f.fixed if n in reduced}
        if self.subject.screen is not None and now is not f and same:
            start = now.x  # a long record: the fit without the candidate is the current one, converged already
        without = self.subject.fit(reduced, start, free, budget)
        k = cand.df if cand.df is not None else len([n for n in own if n not in f.fixed])
        p = float(chi2_sf(self.subject.statistic(f)(without.J, f.J), max(k, 1)))
        self.removals[cand.effect] = Removal(f, budget, p, without)
        return p, without

    def round(self) -> bool:
        """One round: rank the candidates against the current fit and try to add the best accepted one. False when
        the loop stops: the residual is at the noise, no candidate is left or accepted, or the data cannot tell the
        best from another."""
        subject, current = self.subject, self.current
        specs = subject.specs
        todo = [
            c for e, c in specs.items()
            if e not in subject.declared and e not in self.claimed and e not in self.dropped
            and not (c.kind == "parameter" and c.unknowns[0] in current.names)
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
        on = self.basis()
        best = self.choose(self.rank(todo, on), on)
        if best is None:
            return False
        self.try_claim(best, len(todo))
        return True

    def basis(self) -> tuple[Subject, Fit, tuple]:
        """What a round tests against: the subject, the current fit and its validation J; a long record's on its
        screening window, the current model re-fitted there first (the LR is what each candidate adds)."""
        subject, current, current_v = self.subject, self.current, self.current_v
        if subject.screen is not None:
            subject = subject.screen
            free = np.array([n not in current.fixed for n in current.names])
            current = subject.fit(current.names, current.x, free, self.candidate_budget)  # (the linear car's by LM)
            current_v = subject.validation_J(current.names, current.x)
        return subject, current, current_v

    def rank(self, todo: list[Candidate], on: tuple[Subject, Fit, tuple]) -> list[Ranked]:
        """The candidates `todo` ranked against the current fit `on` (`basis`; the round recorded and said)."""
        subject, current, current_v = on
        # A long record's candidates are fitted one at a time: two fits at once on its window (their working sets and
        # the threads' malloc arenas) set the 60 s diagnosis's peak memory, 15-20 MiB above one; each fit's batches of
        # cars still run on every core in the kernel (issue 26: +0.5-1.5 s of 12 s).
        windowed = self.subject.screen is not None
        stage = f"round {len(self.rounds) + 1} candidates"
        self.progress(stage, 0, len(todo))
        tests, skipped, scores = len(todo), [], {}
        chi2 = subject.noise_limit is not None  # J is chi² per sample and the LR chi2_statistic: the score applies
        if chi2 and self.rounds and self.claim and all(c.kind == "parameter" and len(c.unknowns) == 1 for c in todo):
            todo, skipped = self.prescreen(todo, subject, current, current_v, tests)
        elif chi2 and self.claim:
            todo, skipped, scores = self.screen_effects(todo, subject, current, current_v, tests)
        if skipped:  # the tests the score settled are done
            self.progress(stage, len(skipped), tests)

        def critical(k: int) -> float:
            return float(chi2_isf(self.level(tests), k))

        def fit(cands: list[Candidate], before: int, beat: float = 0.0) -> list[Ranked]:
            return rank_candidates(
                cands, current, current_v, lambda names, cand: self.make_problem(names, cand, subject),
                subject.validation_J, subject.residual_count,
                self.alpha, self.candidate_budget, statistic=subject.statistic(current), min_gain=subject.min_gain,
                claim=self.claim, scale=subject.scale(current),
                prior={r.effect: r for r in self.rounds[-1]} if self.rounds else None,
                on_done=lambda n: self.progress(stage, before + n, tests), tests=tests,
                make_linear=lambda names, cand: self.make_linear(names, cand, subject), car=car, beat=beat,
                threads=1 if windowed else None,
            ) if cands else []  # fmt: skip

        def car() -> NDArray | None:  # the current fit's Jacobian, once per round (the effects' screening)
            if "J" not in jacobian:
                J, _ = forward_jacobian(subject.problem_for(current.names)[0], current.x)
                jacobian["J"] = J if np.all(np.isfinite(J)) else None
            return jacobian["J"]

        jacobian: dict[str, NDArray | None] = {}

        stops = chi2 and self.claim  # the effects' fits stop where they cannot beat the best known parameter or sensor
        first = [c for c in todo if c.kind in BEATERS] if scores or stops else todo  # known parameters, sensors first
        sensors = [c for c in first if c.kind == "sensor"] if stops else []  # and of those the sensors: a known
        ranked = fit(sensors, len(skipped))  # parameter's fit stops where it cannot beat the best sensor correction
        top = max((r.statistic for r in ranked if r.accepted), default=0.0)
        ranked += fit([c for c in first if c not in sensors], len(skipped) + len(sensors), top)
        rest = [c for c in todo if c not in first]
        rest, beaten = cannot_win(rest, scores, ranked, current, current_v, critical, subject.residual_count)
        if beaten:
            self.note(
                f"round {len(self.rounds) + 1}: {', '.join(r.effect for r in beaten)} not fitted: twice the score "
                "statistic (reported as the LR) and the critical LR fall short of the best known parameter's or "
                "sensor correction's LR, so they cannot win the round"
            )
            self.progress(stage, len(skipped) + len(ranked) + len(beaten), tests)
        best = max((r.statistic for r in ranked if r.accepted and r.kind in BEATERS), default=0.0)
        rest = fit(rest, len(skipped) + len(first) + len(beaten), best if stops else 0.0)
        if any(r.stopped for r in ranked + rest):
            self.note(
                f"round {len(self.rounds) + 1}: the fits of {', '.join(r.effect for r in ranked + rest if r.stopped)} "
                f"stopped after {STOP_STEPS} steps: {STOP_FACTOR:g} x the LR reached (reported, a lower bound) and the "
                "critical LR fall short of the best known parameter's or sensor correction's LR, so they cannot win "
                "the round"
            )
        ranked = sorted(ranked + rest + skipped + beaten, key=lambda r: -r.statistic)
        self.rounds.append(tuple(ranked))
        self.say("candidates: " + ", ".join(f"{r.effect} LR={r.statistic:.3g}" for r in ranked))
        return ranked

    def prescreen(
        self, todo: list[Candidate], subject: Subject, current: Fit, current_v: tuple, tests: int
    ) -> tuple[list[Candidate], list[Ranked]]:  # fmt: skip
        """A later round's known parameters (one unknown each): Rao's score statistic of every one from one Jacobian
        at the current fit (attribution.score_statistics); those below SCORE_SKIP of the critical LR cannot be
        accepted and are not fitted: their test reports the score statistic as its LR (its first-order value)."""
        t0 = time.perf_counter()
        new = tuple(c.unknowns[0] for c in todo)
        problem, start = subject.problem_for(current.names + new)
        D = len(current.names)
        x = np.concatenate([current.x, start[D:]])
        free = np.array([n not in current.fixed for n in current.names] + [False] * len(new))
        score = score_statistics(problem, x, free, range(D, len(x)))
        critical = chi2_isf(self.level(tests), 1)
        fit, skipped = [], []
        for c, S in zip(todo, score, strict=True):
            if not (np.isfinite(S) and S < SCORE_SKIP * critical):
                fit.append(c)
                continue
            k = c.df if c.df is not None else 1
            R = subject.residual_count
            skipped.append(Ranked(
                effect=c.effect, added=(c.unknowns[0],), k=k, J=current.J - S / R, statistic=float(S),
                p_value=chi2_sf(S, k), bic_margin=S - k * math.log(R), validation_J=current_v[0], accepted=False,
                fit=current, seconds=time.perf_counter() - t0, kind=c.kind, validation_per_file=current_v[1],
                screened=True,
            ))  # fmt: skip
        return fit, skipped

    def screen_effects(
        self, todo: list[Candidate], subject: Subject, current: Fit, current_v: tuple, tests: int
    ) -> tuple[list[Candidate], list[Ranked], Scores]:  # fmt: skip
        """score.screen_effects against the current fit (the basis of its derivatives from the exact sensitivities
        where the model is the linear car): the effects to fit, those not fitted, every screened effect's score
        (and the unknowns it adds)."""
        free = np.array([n not in current.fixed for n in current.names])
        problem = subject.problem_for(current.names)[0]
        linear = subject.linear_for(current.names) if subject.linear_for is not None else None
        basis = fitted_basis(problem, current.x, free, linear) if any(screenable(c) for c in todo) else None
        if basis is None:
            return todo, [], {}
        return screen_effects(
            todo, current, current_v, basis, lambda c: self.make_problem(current.names, c, subject),
            lambda k: float(chi2_isf(self.level(tests), k)), subject.residual_count,
        )  # fmt: skip

    def choose(self, ranked: list[Ranked], on: tuple[Subject, Fit, tuple]) -> Ranked | None:
        """The best accepted candidate, a known parameter (or two, `pair_test`, against the round's fit `on`)
        explaining the residual as well preferred; None when none is accepted or the data cannot tell it from
        another."""
        best = next((r for r in ranked if r.accepted), None)
        if best is None:
            return None
        simpler = parsimonious(ranked, best, self.alpha)
        level = self.level(len(ranked))
        pair = None if simpler else pair_test(on[0], on[1], ranked, best, level, self.candidate_budget)
        if simpler is not None:
            self.note(
                f"{simpler.effect} explains the residual as well as {best.effect} (LR {simpler.statistic:.4g} "
                f"against {best.statistic:.4g}): the known parameter is preferred"
            )
            best = simpler
        elif pair is not None:
            self.note(pair.describe())
            best = pair.first
        # the pair's second is no rival of its first: the data need both (it is tested again in the next round)
        rival = undistinguished([r for r in ranked if pair is None or r is not pair.second], best, self.alpha)
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
        free = np.ones(len(names), dtype=bool)
        if set(shapes) & set(names):  # their intervals (D + 1 simulations) only where a shape parameter may be held
            free = identifiable(names, x0, fisher_ci(problem, x0, subject.scale(best.fit)), shapes)
        refit = subject.fit(names, x0, free, self.refit_budget)  # to SCREEN_TOL: the final polish goes to 1e-12
        best_J = best.fit.J
        if subject.screen is not None:  # the candidate was fitted on the screening window: its J on the whole record
            best_J = subject.J_at(Fit(names, x0, best_J, 0)).J
        if refit.J > best_J:  # keep the candidate's fit if the re-fit found nothing better
            refit = Fit(names, x0, best_J, refit.evaluations, best.fit.fixed)
        return problem, names, refit

    def try_claim(self, best: Ranked, candidates: int) -> None:
        """Re-fit with `best` (one of `candidates` tested) and claim it if its strength interval excludes its null,
        it is still needed after the re-fit and it lowers the validation J; else it is dropped."""
        cand = self.subject.specs[best.effect]
        stage = f"round {len(self.rounds)} re-fit with {best.effect}"
        self.progress(stage, 0, 1)
        problem, names, refit = self.refit(best)
        self.progress(stage, 1, 1)
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

    def swap_claims(self) -> None:
        """Each claimed effect a known parameter of its round nearly matched: that parameter in its place, claimed
        instead, when it explains the record as well (claims.swap_test)."""
        specs = self.subject.specs
        for e in [e for e in self.claimed if specs[e].kind == "effect"]:
            other = rival(self.rounds, e, self.current.names)
            if other is None:
                continue
            swap = swap_test(
                self.subject, self.current, specs[e], other,
                lambda e=e: self.removal_p(self.current, specs[e], self.refit_budget)[1],
                self.level(len(specs)), self.refit_budget,
            )  # fmt: skip
            if swap is None:
                continue
            v = self.subject.validation_J(swap.fit.names, swap.fit.x)
            self.steps.append(Step(other.effect, self.current.J, swap.fit.J, self.current_v[0], v[0], v[1]))
            self.claimed[self.claimed.index(e)] = other.effect
            self.note(swap.describe(self.current.J))
            self.current, self.current_v = swap.fit, v

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
        self.note_companions()

    def note_companions(self) -> None:
        """Say that a claimed effect's companions (asymmetric damping's cf, cr) were re-fitted with it: their
        meaning changed, so their distance from the configured values is no error of the fit."""
        for effect in self.claimed:
            names = [n for n in self.subject.specs[effect].companions if n in self.current.names]
            if not names:
                continue
            values = ", ".join(f"{n} = {self.current.x[self.current.names.index(n)]:.4g}" for n in names)
            self.notes.append(
                f"{', '.join(names)} were re-fitted with {effect}, which splits them ({values}): with it they are the "
                "centre its own parameters spread around (asymmetric damping: rebound c + dc/2, compression c - dc/2), "
                "not the configured values, and may sit far from them"
            )


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
    progress: ProgressHook | None = None,
) -> Loop:
    """Rank the candidates against `fit`, add the best accepted one (a known parameter before an effect that
    explains no more), re-fit everything (identifiable shape parameters freed), keep it only if its strength
    interval excludes its null and it is still needed; repeat until none is accepted or max_rounds; then
    drop whatever the final model no longer needs. With claim=False only rank once. The candidates are fitted and, at
    equal LR, listed in the subject's order (the library's); `progress` hears of each candidate tested and each
    re-fit."""
    current_v = subject.validation_J(fit.names, fit.x)
    run = _Augmentation(subject, alpha, candidate_budget, refit_budget, claim, say, current=fit, current_v=current_v)
    run.progress = progress or run.progress
    for _ in range(max_rounds if claim else min(max_rounds, 1)):
        if not run.round():
            break
    if claim:  # first a known parameter in place of an effect that imitated it: the checks then on the simpler model
        run.swap_claims()
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
    unexplained: Callable[[], tuple[Unexplained | None, tuple[str, ...]]] = lambda: (None, ()),
    extra_notes: tuple[str, ...] = (),
    unit: Callable[[str], str] = lambda _name: "",
    progress: ProgressHook | None = None,
    **fields,
) -> Diagnosis:
    """Run the loop from the declared fit (no claims when the data fail `quality`) and report the outcome;
    `chi2_residuals` is how many residuals the final chi² per sample averages (its noise limit);
    `unexplained()`: the strut force the declared model misses (against the declared model: what the library added
    did not explain it) and its notes, asked for only where it is read: reported when the residual stays above the
    noise, and compared with the final model when the loop selected anything (an imitation); `progress`: the loop's
    steps;
    `unit` gives a parameter's SI unit (the config's `unit`); `fields` are the Diagnosis's descriptive fields
    (validation and noise sources, system, J definition)."""
    rounds = max_rounds if quality.ok else (0 if quality.before_fit else 1)  # a failed pre-check: no fits at all
    loop = augment(
        subject, fit, alpha=alpha, max_rounds=rounds, candidate_budget=candidate_budget,
        refit_budget=refit_budget, claim=quality.ok, say=say, progress=progress,
    )  # fmt: skip
    after = report(loop.fit, loop.effects) if loop.fit is not fit else before
    limit = chi2_limit(chi2_residuals)
    incomplete = after.chi2_per_sample is not None and after.chi2_per_sample > limit
    # The estimate (~0.4 s of a 3 s diagnosis) only where it is read: a residual left, or terms that may imitate a law.
    estimate, estimate_notes = unexplained() if quality.ok and (incomplete or loop.effects) else (None, ())
    uncertainty = compare_reports(loop.effects, before.names, after, estimate) if quality.ok else None
    imitation = uncertainty is not None and uncertainty.imitates
    left = estimate if quality.ok and (incomplete or imitation) else None
    return Diagnosis(
        before=before,
        after=after,
        rounds=loop.rounds,
        selected=loop.effects,
        alpha=alpha,
        wall_s=time.perf_counter() - t_start,
        steps=loop.steps,
        quality=quality,
        notes=loop.notes + estimate_notes + extra_notes,
        chi2_limit=limit,
        unexplained=left,
        units={n: unit(n) for n in dict.fromkeys(before.names + after.names)},
        model_uncertainty=uncertainty,
        **fields,
    )
