"""Score statistics of the effects: what freeing an effect's strengths would gain to first order at the current fit,
from one basis of the fit's derivatives and a few simulations per effect, so that the loop fits only the effects that
could be accepted (loop._Augmentation.screen_effects; the known parameters' own are attribution.score_statistics)."""

from __future__ import annotations

import itertools

import numpy as np
from numpy.typing import NDArray

from ..optimizers.base import Problem
from .attribution import Candidate, _jacobian, restricted


def fitted_basis(problem: Problem, x: NDArray, free: NDArray, linear: Problem | None = None) -> NDArray | None:
    """(R, d) an orthonormal basis of the residuals' derivatives along the fit's `free` unknowns at x (the columns a
    score statistic is taken orthogonal to): from the exact sensitivities of `linear` (the same problem on the exact
    integrator, the linear car) when given and all are free, else forward differences of `problem` (one batch);
    None where they are not finite."""
    free = np.asarray(free, dtype=bool)
    got = linear.linearised(np.asarray(x, dtype=float)) if linear is not None and free.all() else None
    if got is not None:
        jac = got[2]
    else:
        jac, _ = _jacobian(restricted(problem, x, free), np.asarray(x, dtype=float)[free])
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
    starts of its shape parameters (the force at zero strength does not depend on them). It is the first-order LR
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
        if not np.all(np.isfinite(R)):
            return float("nan")
        r = R[0]
        best = 0.0
        for i in range(len(starts)):
            block = slice(1 + i * len(cols), 1 + (i + 1) * len(cols))
            steps = np.array([X[1 + i * len(cols) + m, j] - X[0, j] for m, j in enumerate(cols)])
            jc = ((R[block] - r[None, :]) / steps[:, None]).T
            jc = jc - basis @ (basis.T @ jc)
            g, H = jc.T @ r, jc.T @ jc
            for m in map(np.array, subsets):
                s_m = -np.linalg.lstsq(H[np.ix_(m, m)], g[m], rcond=None)[0]
                if np.all((sign[m] == 0) | (sign[m] * s_m >= 0)):
                    best = max(best, float(-g[m] @ s_m))
    return best
