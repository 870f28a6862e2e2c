"""Score statistics of the effects: what freeing an effect's strengths would gain to first order at the current fit,
from one basis of the fit's derivatives and a few simulations per effect, so that the loop fits only the effects that
could be accepted (loop._Augmentation.screen_effects; the known parameters' own are attribution.score_statistics)."""

from __future__ import annotations

import itertools
import math
import time
from collections.abc import Callable

import numpy as np
from numpy.typing import NDArray

from ..optimizers.base import Problem, forward_jacobian
from .attribution import BEATERS, SCORE_SKIP, Candidate, Fit, Ranked, restricted, screenable
from .tails import chi2_sf

Scores = dict[str, tuple[float, tuple[str, ...]]]  # effect -> its score statistic and the unknowns it adds
WIN_FACTOR = 2.0  # an effect is fitted unless WIN_FACTOR x its score + the critical LR is below the best parameter's LR


def fitted_basis(problem: Problem, x: NDArray, free: NDArray, linear: Problem | None = None) -> NDArray | None:
    """(R, d) an orthonormal basis of the residuals' derivatives along the fit's `free` unknowns at x (the columns a
    score statistic is taken orthogonal to): from the exact sensitivities of `linear` (the same problem on the exact
    integrator, the linear car) when given and all are free, else forward differences of `problem` (one batch);
    None where they are not finite."""
    free = np.asarray(free, dtype=bool)
    exact = linear is not None and linear.linearised is not None and free.all()  # (a long record's has `normal` only)
    got = linear.linearised(np.asarray(x, dtype=float)) if exact else None
    if got is not None:
        jac = got[2]
    else:
        jac, _ = forward_jacobian(restricted(problem, x, free), np.asarray(x, dtype=float)[free])
    if not np.all(np.isfinite(jac)):
        return None
    q, s, _ = np.linalg.svd(jac, full_matrices=False)
    return q[:, s > s[0] * 1e-12] if s.size and s[0] > 0 else q[:, :0]


def effect_score(problem: Problem, x0: NDArray, cand: Candidate, basis: NDArray) -> float:
    """Rao's score statistic of an effect whose force is proportional to its strengths (`cand.linear`), the strengths
    at their null (zero) in x0 (the current fit, then the candidate's unknowns), one-sided where the null is on the
    strength's search bound (a friction or a damping cannot be negative): the largest fall of |r + Jc s|² over the
    steps s the box allows (the exact non-negative least-squares gain, over the subsets of strengths for the few a
    candidate has), with Jc the residuals' forward differences along the strengths less their projection on `basis`
    (fitted_basis: the current fit's free unknowns) and r the residual at x0; the largest over the candidate's
    starts of its shape parameters (the force at zero strength does not depend on them) at which the response is
    finite. It is the first-order LR
    of freeing the strengths at that shape (attribution's chi2_statistic); NaN where a residual is not finite. One
    batch of 1 + starts x strengths simulations."""
    names = list(problem.names)
    lo, hi = problem.lower, problem.upper
    cols = [names.index(n) for n in cand.strength if n in names]
    h = 1e-6 * (hi - lo)
    null = np.clip([cand.null.get(names[j], 0.0) for j in cols], lo[cols], hi[cols])
    sign = np.where(null <= lo[cols], 1.0, np.where(null >= hi[cols], -1.0, 0.0))  # allowed direction (0: both)
    rows = [np.clip(np.asarray(x0, dtype=float), lo, hi)]
    rows[0][cols] = null
    starts = cand.starts or ({},)
    for s in starts:
        x = rows[0].copy()
        for k, v in s.items():
            if k in names and k not in cand.strength:
                x[names.index(k)] = np.clip(v, lo[names.index(k)], hi[names.index(k)])
        for j in cols:
            q = x.copy()
            q[j] += h[j] if q[j] + h[j] <= hi[j] else -h[j]
            rows.append(q)
    X = np.array(rows)
    subsets = [m for m in itertools.product((False, True), repeat=len(cols)) if any(m)]
    with np.errstate(all="ignore"):
        _, R = problem.residuals(X)
        r = R[0]
        if not np.all(np.isfinite(r)):
            return float("nan")
        best, tried = 0.0, 0
        for i in range(len(starts)):
            block = slice(1 + i * len(cols), 1 + (i + 1) * len(cols))
            if not np.all(np.isfinite(R[block])):  # a shape the response diverges at (a gas column shorter than
                continue  # the stroke): no start there, as the candidate's fit finds
            tried += 1
            steps = np.array([X[1 + i * len(cols) + m, j] - X[0, j] for m, j in enumerate(cols)])
            jc = ((R[block] - r[None, :]) / steps[:, None]).T
            jc = jc - basis @ (basis.T @ jc)
            g, H = jc.T @ r, jc.T @ jc
            for m in map(np.array, subsets):
                s_m = -np.linalg.lstsq(H[np.ix_(m, m)], g[m], rcond=None)[0]
                if np.all((sign[m] == 0) | (sign[m] * s_m >= 0)):
                    best = max(best, float(-g[m] @ s_m))
    return best if tried else float("nan")


def score_ranked(cand: Candidate, S: float, added: tuple[str, ...], current: Fit, current_v: tuple, R: int,
                 seconds: float) -> Ranked:  # fmt: skip
    """The test of a candidate that was not fitted: its score statistic S stands for its LR (its first-order
    value), J the current fit's less S / R, nothing accepted, the fit the current one."""
    k = cand.df if cand.df is not None else len(cand.strength)
    return Ranked(
        effect=cand.effect, added=added, k=k, J=current.J - S / R, statistic=float(S), p_value=chi2_sf(S, k),
        bic_margin=S - k * math.log(R), validation_J=current_v[0], accepted=False, fit=current, seconds=seconds,
        kind=cand.kind, validation_per_file=current_v[1], screened=True,
    )  # fmt: skip


def screen_effects(
    todo: list[Candidate], current: Fit, current_v: tuple, basis: NDArray,
    make_problem: Callable[[Candidate], tuple[Problem, NDArray]], critical: Callable[[int], float], R: int,
) -> tuple[list[Candidate], list[Ranked], Scores]:  # fmt: skip
    """The effects whose force is proportional to their strengths: Rao's score statistic of the strengths at zero
    against the current fit (effect_score, the largest over the starts of their shape; `basis` the current fit's
    derivatives, `make_problem(candidate)` the augmented problem and the start of its unknowns); those below
    SCORE_SKIP of the critical LR (`critical(k)`) cannot be accepted and are not fitted (as the loop's `prescreen`
    does for a later round's known parameters), their test reporting the score statistic as its LR. Returns the
    candidates to fit, the tests of those not fitted and every screened effect's score."""
    fit, skipped, scores = [], [], {}
    for c in todo:
        if not screenable(c):
            fit.append(c)
            continue
        t0 = time.perf_counter()
        problem, start = make_problem(c)
        S = effect_score(problem, np.concatenate([current.x, start]), c, basis)
        k = c.df if c.df is not None else len(c.strength)
        if not (np.isfinite(S) and S < SCORE_SKIP * critical(k)):
            fit.append(c)
            if np.isfinite(S):
                scores[c.effect] = (S, tuple(problem.names[len(current.names) :]))
            continue
        added = tuple(problem.names[len(current.names) :])
        skipped.append(score_ranked(c, S, added, current, current_v, R, time.perf_counter() - t0))
    return fit, skipped, scores


def cannot_win(
    rest: list[Candidate], scores: Scores, fitted: list[Ranked], current: Fit, current_v: tuple,
    critical: Callable[[int], float], R: int,
) -> tuple[list[Candidate], list[Ranked]]:  # fmt: skip
    """The screened effects of `rest` that cannot win the round: WIN_FACTOR x their score (an effect's fitted LR has
    been up to 1.78 x its score over the library's effect and mis-set parameter cases: a shape parameter moving far
    from the starts the score is taken at; tests/test_score_prescreen.py) plus the critical LR of its test below the
    LR of the best accepted known parameter or sensor correction (BEATERS) among the `fitted` tests. The best is then
    that one whatever their fits would give (parsimony and the rivalry of `undistinguished` compare an effect with the
    best only when the best is an effect), so they are not fitted; their tests report the score as the LR. Returns the
    candidates to fit and those tests."""
    best = max((r.statistic for r in fitted if r.accepted and r.kind in BEATERS), default=0.0)
    keep, beaten = [], []
    for c in rest:
        S, added = scores.get(c.effect, (np.nan, ()))
        k = c.df if c.df is not None else len(c.strength)
        if np.isfinite(S) and WIN_FACTOR * S + critical(k) < best:
            beaten.append(score_ranked(c, S, added, current, current_v, R, 0.0))
        else:
            keep.append(c)
    return keep, beaten
