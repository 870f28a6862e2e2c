"""The tests of a claim: its own unknowns, whether its strength interval excludes its null, the record of its removal
test, the swap test of the final model and the pair test of a round.

The swap test: an effect was chosen in its round, on the screening data, over known parameters that explained
nearly as much (a Bouc-Wen element that never yields stands in for a stiffer front spring, and on a long record's
5 s window its three unknowns can beat the one of kf). At the end, on the whole record and beside every other claim,
the strongest such parameter is fitted in the effect's place; it is preferred when it explains the record as well,
by the parsimony rule a round applies (attribution.parsimonious): its LR over the model with neither short of the
effect's by less than the critical value of chi²(k), or at least PARSIMONY_SHARE of it.

The pair test applies that rule in the round to two known parameters at once, so that the detour is not taken: two
mis-set parameters (kf and cr) each explain part of a residual a three-unknown Bouc-Wen element spans alone."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .attribution import PARSIMONY_SHARE, Candidate, Fit, Ranked
from .subject import Subject
from .tails import chi2_isf

SWAP_SHARE = 0.5  # a known parameter whose LR reached this share of the effect's in the effect's round is tried instead


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


@dataclass(frozen=True)
class Removal:
    """A removal test (`removal_p`) of `fit` within `budget`: its p-value and the fit without the candidate."""

    fit: Fit
    budget: int
    p: float
    without: Fit


@dataclass(frozen=True)
class Swap:
    """A claimed effect replaced by a known parameter: the fit with the parameter in its place, the effect's LR over
    that fit and the critical LR it fell short of (or, where it did not, the share of the effect's LR the parameter
    reached over the model with neither)."""

    effect: str
    parameter: str
    fit: Fit
    gap: float
    critical: float
    share: float | None = None

    def describe(self, J_effect: float) -> str:
        """The note that says the swap and why (J_effect: the training J with the effect)."""
        why = (
            f"the effect's LR over that fit, {self.gap:.3g}, is short of the critical {self.critical:.3g}"
            if self.share is None
            else f"{self.parameter} reaches {self.share:.0%} of the effect's LR over the model with neither"
        )
        return (
            f"{self.effect} swapped for {self.parameter} at the end: with {self.parameter} in its place J = "
            f"{self.fit.J:.4g} against {J_effect:.4g}; {why}, so the known parameter explains the record as well"
        )


def rival(rounds: Sequence[Sequence[Ranked]], effect: str, names: tuple[str, ...]) -> Ranked | None:
    """The strongest accepted known parameter of the round that chose `effect` (the last that ranked it), not in the
    model `names` yet, whose LR there reached SWAP_SHARE of the effect's; None if none."""
    rnd, mine = next(((rnd, r) for rnd in reversed(rounds) for r in rnd if r.effect == effect), ((), None))
    if mine is None:
        return None
    rivals = [
        r for r in rnd if r.kind == "parameter" and r.accepted and not set(r.added) & set(names)
        and r.statistic >= SWAP_SHARE * mine.statistic
    ]  # fmt: skip
    return max(rivals, key=lambda r: r.statistic, default=None)


def swap_test(
    subject: Subject, current: Fit, effect: Candidate, parameter: Ranked, without: Callable[[], Fit], level: float,
    budget: int,
) -> Swap | None:  # fmt: skip
    """Fit the model `current` with the known parameter `parameter` (from its estimate in its round) in place of the
    claimed effect `effect`. The Swap when the parameter explains the record as well (the parsimony rule at `level`;
    `without()`, the removal test's fit of the model with neither, is asked for only where the effect's LR over the
    parameter's fit is not short of the critical value) and its interval excludes its configured value; else None."""
    own = own_unknowns(effect, current.names)
    kept = tuple(n for n in current.names if n not in own)
    names = kept + parameter.added
    start = subject.problem_for(names)[1]
    at = [parameter.fit.x[parameter.fit.names.index(n)] if n in parameter.fit.names else s
          for n, s in zip(parameter.added, start[len(kept) :], strict=True)]  # fmt: skip
    x0 = np.concatenate([current.x[[current.names.index(n) for n in kept]], at])
    fit = subject.fit(names, x0, np.array([n not in current.fixed for n in names]), budget)
    lr = subject.statistic(current)
    k = effect.df if effect.df is not None else len([n for n in own if n not in current.fixed])
    gap, critical, share = lr(fit.J, current.J), float(chi2_isf(level, max(k, 1))), None
    if gap >= critical:  # short of the effect by more than chance: as well only if it reaches PARSIMONY_SHARE of it
        J0 = without().J
        share = lr(J0, fit.J) / max(lr(J0, current.J), 1e-300)
        if share < PARSIMONY_SHARE:
            return None
    if not strength_excludes_null(subject.specs[parameter.effect], fit, subject.intervals(fit)):
        return None
    return Swap(effect.effect, parameter.effect, fit, gap, critical, share)


@dataclass(frozen=True)
class Pair:
    """Two known parameters fitted together in a round that an effect won: their joint LR over the round's current
    fit, the effect's, and the critical LR of chi²(k_effect) the parsimony rule allows between them."""

    first: Ranked
    second: Ranked
    statistic: float
    effect: Ranked
    critical: float

    def describe(self) -> str:
        """The note that says why the round's stronger parameter is preferred to the effect."""
        return (
            f"{self.first.effect} and {self.second.effect} together explain the residual as well as "
            f"{self.effect.effect} (LR {self.statistic:.4g} with 2 unknowns against {self.effect.statistic:.4g} with "
            f"{self.effect.k}): the known parameters are preferred, {self.first.effect} first"
        )


def pair_test(subject: Subject, current: Fit, ranked: Sequence[Ranked], best: Ranked, level: float,
              budget: int) -> Pair | None:  # fmt: skip
    """The parsimony rule for two known parameters at once: where the effect `best` won the round (`ranked`, against
    `current` on `subject`) with at least two unknowns and no single known parameter explained as much, the round's
    two strongest accepted known parameters fitted together from their own estimates. The Pair when they explain the
    residual as well (LR short of the effect's by less than the critical value of chi²(k) at `level`, or at least
    PARSIMONY_SHARE of it); else None. Two mis-set parameters (kf and cr) each explain part of a residual that a
    three-unknown Bouc-Wen element spans alone; without this the loop claims the element, fits it on the whole
    record, and only swaps it out at the end."""
    # (fitted ones: a score-screened parameter's test holds no estimate of it)
    params = [
        r for r in ranked if r.kind == "parameter" and r.accepted and len(r.added) == 1 and r.added[0] in r.fit.names
    ]
    if best.kind != "effect" or best.k < 2 or len(params) < 2 or current.fixed:
        return None
    first, second = params[0], params[1]
    names = current.names + first.added + second.added
    if len(set(names)) != len(names):
        return None
    at = [r.fit.x[r.fit.names.index(r.added[0])] for r in (first, second)]
    fit = subject.fit(names, np.concatenate([current.x, at]), np.ones(len(names), dtype=bool), budget)
    lr = subject.statistic(current)(current.J, min(fit.J, current.J))
    critical = float(chi2_isf(level, best.k))
    if best.statistic - lr < critical or lr >= PARSIMONY_SHARE * best.statistic:
        return Pair(first, second, lr, best, critical)
    return None
