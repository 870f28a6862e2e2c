"""Attribution: which missing effect, or which mis-set known parameter, explains the residual?

Candidates are of two kinds: the library's effects the config does not declare, and the configured "known"
parameters (springs kf, kr; dampers cf, cr; tyres ktf, ktr; anti-roll bar kR; unsprung masses mf, mr; on a
bench the damper model's fixed parameters), named ``parameter:<name>`` (SPEC section 5). For each, a
candidate fit (the current unknowns plus the candidate's, from the current fit) and then

* the likelihood-ratio statistic LR = (chi²_before - chi²_with) x R, with chi² the noise-weighted residual
  power per sample over the R training residuals: 2 x the gain in Gaussian log-likelihood with the noise
  sigma of the task; the nested model is the candidate switched off (strength zero, or the parameter at its
  configured value), so the fit with it is never worse than without (LR >= 0);
* its p-value from chi²(k), k the number of parameters the fit freed;
* a BIC margin LR - k ln R (positive: the candidate pays for its parameters);
* the validation chi² per sample (the --validate run(s), else held-out blocks of the data).

A candidate is accepted when p < alpha / (number of candidates) (Bonferroni) AND it lowers the validation J
(on a bench with several held-out runs: on every one of them). Candidates are ranked by LR, best first.

Shapes are identified, not assumed: an effect's shape parameters (a Bouc-Wen loop's yield, a friction or
switch velocity, a gas column, a contact stiffness) start from several values spread over their physically
plausible range; at each start the strengths (per axle) come from one linearised least-squares step (the
force is proportional to them), all starts in two batched evaluations; the best start's shape parameters
whose 95 % interval (Fisher information) is narrower than SHAPE_IDENTIFIABLE of their value are freed in the
fit, the others stay at the start's value and the candidate says so (``fixed``).

Asymmetric damping replaces the configured damping by a rebound and a compression value: its test frees only
dc (per axle), and once it is selected the re-fit also frees the damping it splits (cf, cr), whose pair need
not average to the configured value (a test with them free would credit a mis-set damper to the effect).

Search boxes: the effects' physical bounds (effects.py) narrowed to a range a passenger-car strut can have;
known parameters within identify.bounds of their configured value (the car) or BENCH_PARAMETER_RANGE of it
(a bench). Candidate fits run in parallel threads (the compiled kernels release the GIL).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..core.allocator import release_if_handing_back
from ..core.pools import as_done, shared_pool
from ..core.result import Result
from ..models.effects import LIBRARY, CandidateForm, CarScale
from ..models.faults import Channel, fault_of
from ..optimizers.base import BudgetExhausted, Problem, Search, forward_jacobian
from ..optimizers.lsq import BOUND_SHARE, gauss_newton, polish
from ..sim.kernel import available_cores
from .jacobians import exact_normal, forward_normal, restricted
from .starts import lower_start, screen_starts
from .stops import STOP_STEPS, Stopped, cannot_win_after, stoppable
from .tails import chi2_isf, chi2_sf

ALPHA = 1e-3  # family-wise significance level of the candidate tests (Bonferroni over candidates)
CANDIDATE_BUDGET = 150  # model evaluations of one candidate's fit (after the screening of its starts)
DISTINCT_VALIDATION = 0.1  # validation J this much lower tells the best candidate from a close runner-up
BEATERS = ("parameter", "sensor")  # fitted before a round's effects: an effect short of their best cannot win it
# (an effect only rivals effects, `undistinguished`, and parsimony prefers a parameter to an effect, not to a sensor)
PARSIMONY_SHARE = 0.9  # a known parameter explaining this share of an effect's LR is preferred to it
SHAPE_IDENTIFIABLE = 0.5  # a shape parameter is freed when its 95 % half-width is below this fraction of it
SCREEN_TOL = 1e-7  # candidate fits stop at this relative change of the cost (LR to about 1e-7 R)
SCORE_SKIP = (
    0.25  # a later round's known parameter whose score statistic is below this share of the critical LR is not fitted
)
Z95 = 1.959963984540054
MISFIT_BLOCKS = 30  # stretches of the record the misfit-robust (sandwich) intervals compare
PARAMETER_GROUPS = {
    "springs": ("kf", "kr"),
    "dampers": ("cf", "cr"),
    "tyres": ("ktf", "ktr"),
    "anti-roll bar": ("kR",),
    "unsprung masses": ("mf", "mr"),
}  # the car's known parameters a diagnosis may free, as an engineer groups them
PARAMETER_PREFIX = "parameter:"


@dataclass(frozen=True)
class Candidate:
    """How one candidate enters a fit: the unknowns it adds, their search range and start.

    `strength`: the unknowns whose 95 % interval must exclude their `null` value (zero, or the configured
    value of a known parameter) for the candidate to be claimed; `starts`: values of its shape (and, where
    the force is not proportional to it, strength) parameters to start from; `linear` says the force is
    proportional to the strengths (screened by one linearised step)."""

    effect: str  # canonical effect name, or parameter:<name>
    unknowns: tuple[str, ...]  # effect.param names, and vehicle parameters it frees
    limits: dict[str, tuple[float, float]] = field(default_factory=dict)
    start: dict[str, float] = field(default_factory=dict)
    shape: tuple[str, ...] = ()  # shape parameters, freed where the data can tell them
    shape_limits: dict[str, tuple[float, float]] = field(default_factory=dict)
    kind: str = "effect"  # "effect", "parameter" or "sensor" (a fault of the measurement chain)
    strength: tuple[str, ...] = ()
    null: dict[str, float] = field(default_factory=dict)
    starts: tuple[dict[str, float], ...] = ()
    linear: bool = True
    group: str = ""  # a known parameter's group (springs, dampers, ...)
    companions: tuple[str, ...] = ()  # known parameters the effect replaces, freed with it once it is selected
    df: int | None = None  # degrees of freedom of its test (None: one per unknown it frees)


def parameter_candidate(name: str, configured: float, group: str = "", limits=None) -> Candidate:
    """Freeing the configured known parameter `name` (its null: the configured value)."""
    return Candidate(
        PARAMETER_PREFIX + name, (name,), dict(limits or {}), {}, kind="parameter", strength=(name,),
        null={name: float(configured)}, linear=False, group=group,
    )  # fmt: skip


def car_parameter_candidates(config) -> list[Candidate]:
    """The car's known parameters (not among the unknowns) as candidates, in PARAMETER_GROUPS order."""
    values = config.vehicle.values()
    unknowns = set(config.identify.unknowns)
    return [
        parameter_candidate(n, values[n], group)
        for group, names in PARAMETER_GROUPS.items()
        for n in names
        if n not in unknowns and values.get(n, 0.0) != 0.0
    ]


def effect_candidate(name: str, form: CandidateForm) -> Candidate:
    """An effect's candidate from the form its module declares (`models.effects`: on the car or on a bench)."""
    return Candidate(
        name, form.unknowns, dict(form.limits), dict(form.start), form.shape, dict(form.shape_limits),
        strength=form.strength, null=dict(form.null), starts=form.starts, linear=form.linear,
        companions=form.companions,
    )  # fmt: skip


def candidate_specs(config, step: float | None) -> dict[str, Candidate]:
    """Every candidate for the car: each registered effect's car form (its ranges may scale with the configured
    damping cf, cr and the RK4 step [s], None on another integrator), in the library's order, then the configured
    known parameters (``parameter:<name>``)."""
    v = config.vehicle.values()
    scale = CarScale(v["cf"], v["cr"], step)
    out = {
        name: effect_candidate(name, e.car_candidate(scale))
        for name, e in LIBRARY.items()
        if e.car_candidate is not None
    }
    out.update({c.effect: c for c in car_parameter_candidates(config)})
    return out


def candidate_ranges(specs: dict[str, Candidate]) -> tuple[dict[str, tuple[float, float]], dict[str, float]]:
    """Every candidate's search ranges (its unknowns' and its shape parameters') and start values, by name."""
    limits: dict[str, tuple[float, float]] = {}
    starts: dict[str, float] = {}
    for c in specs.values():
        limits.update(c.limits)
        limits.update(c.shape_limits)
        starts.update(c.start)
    return limits, starts


@dataclass(frozen=True)
class Fit:
    """A least-squares fit: unknowns, estimate, training chi² per sample, evaluations."""

    names: tuple[str, ...]
    x: NDArray
    J: float
    evaluations: int
    fixed: tuple[str, ...] = ()  # unknowns held at their value in this fit (shapes the data cannot tell)
    stopped: bool = False  # stopped after STOP_STEPS steps: the best point then, not a converged fit (`stoppable`)


def lsq_fit(problem: Problem, x0: NDArray, budget: int, seed: int = 0, tol: float = 1e-12) -> Fit:
    """Trust-region least squares from x0 within `budget` evaluations (the best point seen), to relative
    tolerance `tol`."""
    run = Search(problem, np.random.default_rng(seed), budget)
    try:
        polish(run, x0, tol=tol)
    except BudgetExhausted:
        pass
    x = run.best_x if run.best_x is not None else np.asarray(x0, dtype=float)
    return Fit(tuple(problem.names), x, float(run.best_cost), run.evaluations)


def linear_fit(problem: Problem, linear: Problem, x0: NDArray, budget: int, bounds: bool = True) -> Fit | None:
    """The fit of a linear-car model by Levenberg–Marquardt on `linear`, the same problem on the exact integrator with
    its exact sensitivities (a few evaluations where finite differences take (D + 1) per step), from x0; its J is
    `problem`'s at that point (one more evaluation), so that it compares with the other fits on `problem`'s
    integrator: above `problem`'s own minimum by the square of the integrators' difference (for the car at 1 kHz
    and rk4 about 1e-5 of the LR). Where an unknown ends on its search bound (Levenberg–Marquardt clips its steps into
    the box, which stalls the others' convergence there) the trust region, which handles the bounds, finishes the fit
    on `linear` (to SCREEN_TOL, as a candidate's fit on `problem` would be). None when the linearisation does not hold
    there, J is not finite, or an unknown ends on a bound of a long record's (its `linear` has the summed normal
    equations only; the trust region would hold its R x D Jacobian) or with `bounds` False (a fit that may be stopped:
    the stop counts Levenberg–Marquardt's steps): the caller fits on `problem` instead."""
    run = Search(linear, np.random.default_rng(0), budget)
    try:
        x = gauss_newton(run, np.clip(np.asarray(x0, dtype=float), linear.lower, linear.upper), interior=True)
    except BudgetExhausted:
        x = run.best_x
    best, lo, hi = run.best_x, linear.lower, linear.upper
    on_bound = best is not None and bool(np.any(np.minimum(best - lo, hi - best) <= BOUND_SHARE * (hi - lo)))
    if best is None or (x is None and not on_bound) or (on_bound and (linear.linearised is None or not bounds)):
        return None
    bounded = lsq_fit(linear, best, max(budget - run.evaluations, 1), tol=SCREEN_TOL) if on_bound else None
    x, evaluations = (best, run.evaluations) if bounded is None else (bounded.x, run.evaluations + bounded.evaluations)
    with np.errstate(all="ignore"):
        J = float(problem.cost(x[None, :])[0])
    return Fit(tuple(problem.names), x, J, evaluations + 1) if np.isfinite(J) else None


def fit_free(problem: Problem, x0: NDArray, free: NDArray, budget: int, tol: float = 1e-12) -> Fit:
    """lsq_fit over the `free` unknowns only (the others held at x0); the Fit covers every unknown."""
    free = np.asarray(free, dtype=bool)
    x0 = np.asarray(x0, dtype=float)
    if free.all():
        return lsq_fit(problem, x0, budget, tol=tol)
    sub = lsq_fit(restricted(problem, x0, free), x0[free], budget, tol=tol)
    x = x0.copy()
    x[free] = sub.x
    fixed = tuple(n for n, f in zip(problem.names, free, strict=True) if not f)
    return Fit(tuple(problem.names), x, sub.J, sub.evaluations, fixed)


def misfit_ci(problem: Problem, fit: Fit, blocks: int = MISFIT_BLOCKS) -> NDArray:
    """95 % half-widths that survive a wrong model (NaN for the fixed unknowns): the sandwich (J'J)^-1 S (J'J)^-1
    with S = sum over `blocks` contiguous blocks of the residual entries (stretches of time) of g_b g_b',
    g_b = J_b' r_b: the residual's own correlation within a block is kept, where (J'J)^-1 chi² assumes it white.
    With a right model and white noise it is the usual covariance; with a misfit it grows with what the misfit
    does to the estimate from one stretch of the record to the next."""
    free = np.array([n not in fit.fixed for n in fit.names])
    out = np.full(len(fit.names), np.nan)
    sub = restricted(problem, fit.x, free)
    Jac, r = forward_jacobian(sub, fit.x[free])
    if not (np.all(np.isfinite(Jac)) and np.all(np.isfinite(r))):
        return out
    try:
        inv = np.linalg.inv(Jac.T @ Jac)
    except np.linalg.LinAlgError:
        return out
    edges = np.linspace(0, r.size, max(2, min(blocks, r.size)) + 1).astype(int)
    g = np.array([Jac[a:b].T @ r[a:b] for a, b in zip(edges[:-1], edges[1:], strict=True)])
    g -= g.mean(axis=0)
    cov = inv @ (g.T @ g) * (len(g) / max(len(g) - 1, 1)) @ inv
    d = np.diag(cov)
    out[free] = np.where(d >= 0, Z95 * np.sqrt(np.abs(d)), np.nan)
    return out


def fisher_ci(problem: Problem, x: NDArray, scale: float, linear: Problem | None = None) -> NDArray:
    """95 % half-widths from (J'J)^-1 scale at x, J the Jacobian of the problem's residuals (forward
    differences, one batch; or `linear`'s exact sensitivities, `exact_normal`) and `scale` the variance of one
    residual entry (NaN where singular)."""
    H = exact_normal(linear, x) if linear is not None else None
    H = forward_normal(problem, x) if H is None else H
    if not np.all(np.isfinite(H)):
        return np.full(x.size, np.nan)
    try:
        cov = np.linalg.inv(H) * max(scale, 1e-300)
    except np.linalg.LinAlgError:
        return np.full(x.size, np.nan)
    d = np.diag(cov)
    return np.where(d >= 0, Z95 * np.sqrt(np.abs(d)), np.nan)


def fit_intervals(problem: Problem, fit: Fit, scale: float, linear: Problem | None = None) -> NDArray:
    """95 % half-widths at a fit over its free unknowns (NaN for those it held fixed); `problem` over fit.names;
    `linear`: the same problem on the linear car's exact integrator (`Subject.linear_for`), whose exact
    sensitivities give J'J when every unknown is free (the time-stepping integrator's differ from them by its own
    error, ~(w dt)^4, far below the forward differences' ~1e-4)."""
    free = np.array([n not in fit.fixed for n in fit.names])
    out = np.full(len(fit.names), np.nan)
    exact = linear if linear is not None and free.all() else None
    out[free] = fisher_ci(restricted(problem, fit.x, free), fit.x[free], scale, exact)
    return out


def identifiable(names: Sequence[str], x: NDArray, ci: NDArray, shape: Sequence[str]) -> NDArray:
    """(D,) True for every unknown to free: all but the `shape` ones the data cannot tell (95 % half-width
    above SHAPE_IDENTIFIABLE of the value, or undetermined)."""
    x, ci = np.asarray(x, dtype=float), np.asarray(ci, dtype=float)
    out = np.ones(len(names), dtype=bool)
    for j, n in enumerate(names):
        if n in shape:
            out[j] = bool(np.isfinite(ci[j]) and ci[j] < SHAPE_IDENTIFIABLE * abs(x[j]))
    return out


def candidate_fit(
    problem: Problem, base: Fit, x_added: NDArray, cand: Candidate, budget: int, scale: float,
    prior: dict[str, float] | None = None, car: NDArray | None = None, stop: Callable[[float], bool] | None = None,
) -> Fit:  # fmt: skip
    """A candidate's fit: the best of its starts (and of `prior`, its own estimates from an earlier round),
    its identifiable shape parameters freed, least squares to SCREEN_TOL; `car`: the residuals' derivatives along
    `base`'s unknowns at `base` (R, D), which the screening of the starts steers by (screen_starts). `stop(J)`:
    asked once after STOP_STEPS trust-region steps (1 + STOP_STEPS (d + 1) evaluations of the fit over d free
    unknowns) with the best J so far; True ends the fit there (the Fit `stopped`, at that point). Until then the fit
    is the same as without `stop`, and after it too when it is not stopped."""
    x0 = np.concatenate([base.x, x_added])
    x0 = np.clip(x0, problem.lower, problem.upper)
    extra = (prior,) if prior else ()
    if cand.kind == "parameter" and not (cand.starts or cand.shape) and extra:  # one unknown: the cheaper start
        x0 = lower_start(problem, x0, prior)
    elif cand.starts or cand.linear or extra:
        starts = (*(cand.starts or ({},)), *extra)
        x0 = screen_starts(problem, x0, starts, cand.shape, cand.strength, cand.null, cand.linear, base.x.size, car)
    free = np.ones(x0.size, dtype=bool)
    shapes = [n for n in cand.shape if n in problem.names]
    if shapes:
        free = identifiable(problem.names, x0, fisher_ci(problem, x0, scale), shapes)
    if stop is None:
        return fit_free(problem, x0, free, budget, tol=SCREEN_TOL)
    try:
        return fit_free(stoppable(problem, 1 + STOP_STEPS * (int(free.sum()) + 1), stop), x0, free, budget,
                        tol=SCREEN_TOL)  # fmt: skip
    except Stopped as s:  # (the wrapped problem is the full one: s.x covers every unknown)
        fixed = tuple(n for n, f in zip(problem.names, free, strict=True) if not f)
        return Fit(tuple(problem.names), s.x, s.J, s.evaluations, fixed, stopped=True)


def parameter_fit(
    problem: Problem, base: Fit, x_added: NDArray, cand: Candidate, budget: int,
    make_linear: Callable[[tuple[str, ...], Candidate], Problem | None] | None,
    stop: Callable[[float], bool] | None = None,
) -> Fit | None:  # fmt: skip
    """A known parameter's candidate fit by `linear_fit` where the augmented model is the linear car (`make_linear`
    gives its exact-integrator problem), from the current fit and the configured value; None elsewhere. `stop(J)`:
    asked once after its start and STOP_STEPS accepted Levenberg–Marquardt steps (`stoppable`); True ends the fit
    there (the Fit `stopped`, its J the exact integrator's at that point)."""
    if cand.kind != "parameter" or make_linear is None or base.fixed:
        return None
    linear = make_linear(base.names, cand)
    if linear is None:
        return None
    x0 = np.concatenate([base.x, x_added])
    if stop is None:
        return linear_fit(problem, linear, x0, budget)
    try:
        return linear_fit(problem, stoppable(linear, 1 + STOP_STEPS, stop), x0, budget, bounds=False)
    except Stopped as s:
        return Fit(tuple(problem.names), s.x, s.J, s.evaluations, stopped=True)


@dataclass(frozen=True)
class Ranked(Result):
    """One candidate's test."""

    effect: str
    added: tuple[str, ...]
    k: int
    J: float  # training chi² per sample reached with the candidate
    statistic: float  # likelihood ratio
    p_value: float
    bic_margin: float  # LR - k ln R
    validation_J: float
    accepted: bool
    fit: Fit
    seconds: float
    kind: str = "effect"
    validation_per_file: dict[str, float] | None = None
    fixed: tuple[str, ...] = ()  # shape parameters the data could not tell (held at their start value)
    screened: bool = False  # not fitted: its score statistic stands for its LR (loop's prescreen, score.py)
    stopped: bool = False  # its fit stopped after STOP_STEPS steps (it cannot win the round): LR reached, a lower bound

    def to_json(self) -> dict:
        out = {
            "effect": self.effect,
            "kind": self.kind,
            "statistic": self.statistic,
            "p_value": self.p_value,
            "J": self.J,
            "k": self.k,
            "bic_margin": self.bic_margin,
            "validation_J": self.validation_J,
            "accepted": self.accepted,
            "estimates": dict(zip(self.fit.names, map(float, self.fit.x), strict=True)),
            "shape_fixed": list(self.fixed),
            "fitted": not self.screened,
            "stopped": self.stopped,
        }
        if self.validation_per_file:
            out["validation_J_per_file"] = dict(self.validation_per_file)
        return out


def chi2_statistic(residual_count: int) -> Callable[[float, float], float]:
    """LR for a known noise sigma: (chi²_before - chi²_with) x R, J being the chi² per sample."""
    return lambda J0, J1: max(0.0, (J0 - J1) * residual_count)


def lowers_validation(vJ: float, per: dict[str, float] | None, base_vJ: float,
                      base_per: dict[str, float] | None, min_gain: float) -> bool:  # fmt: skip
    """Does the validation J fall (by the fraction min_gain), and on every held-out run where there are several?"""
    if not (np.isfinite(vJ) and vJ < (1.0 - min_gain) * base_vJ):
        return False
    if per and base_per:
        return all(per[k] < base_per[k] for k in base_per)
    return True


def rank_candidates(
    candidates: list[Candidate],
    base: Fit,
    base_validation: tuple[float, dict[str, float] | None],
    make_problem: Callable[[tuple[str, ...], Candidate], tuple[Problem, NDArray]],
    validation_J: Callable[[tuple[str, ...], NDArray], tuple[float, dict[str, float] | None]],
    residual_count: int,
    alpha: float = ALPHA,
    budget: int = CANDIDATE_BUDGET,
    statistic: Callable[[float, float], float] | None = None,
    min_gain: float = 0.0,
    claim: bool = True,
    scale: float = 1.0,
    prior: dict[str, Ranked] | None = None,
    on_done: Callable[[int], None] | None = None,
    tests: int | None = None,
    make_linear: Callable[[tuple[str, ...], Candidate], Problem | None] | None = None,
    car: Callable[[], NDArray | None] | None = None,
    beat: float = 0.0,
    threads: int | None = None,
) -> list[Ranked]:
    """Test every candidate against the current fit `base`; best (largest LR) first.

    make_problem(names, candidate) gives the augmented problem (its unknowns: names, then the added ones)
    and the start of the added unknowns; validation_J(names, x) the validation J (and per held-out run).
    statistic(J_before, J_with) is the LR (default: chi² with known noise over `residual_count` residuals);
    a candidate must also lower the validation J by the fraction `min_gain` (on every held-out run);
    `scale` is the variance of one residual entry (for the shape parameters' intervals); with claim=False
    nothing is accepted (the data cannot tell); `prior`: each candidate's test of an earlier round, whose
    estimates of its own unknowns are one more start (warm start); `on_done(n)`: n candidates tested so far (called
    from this thread); `tests`: how many candidates the round tests in all (the Bonferroni count; default these);
    `make_linear(names, candidate)`: the augmented problem on the exact integrator with its exact sensitivities, or
    None where the model is not the linear car: a known parameter's candidate is then fitted by `linear_fit`;
    `car()`: the residuals' derivatives (R, D) along `base`'s unknowns at `base` (all free), which the effects'
    screenings steer by; `beat`: the LR of the round's best accepted known parameter or sensor (0: none), which an
    effect's fit stops at when it cannot win the round (`cannot_win_after`); `threads`: how many candidates are
    fitted at once (None: one per core). Candidate fits run in parallel threads."""
    statistic = statistic or chi2_statistic(residual_count)
    level = alpha / max(tests or len(candidates), 1)
    base_vJ, base_per = base_validation
    k_max = max((len(c.unknowns) + len(c.shape) if c.df is None else c.df for c in candidates), default=1)
    margin = float(chi2_isf(level, k_max))

    def one(cand: Candidate) -> Ranked:
        t0 = time.perf_counter()
        problem, x_added = make_problem(base.names, cand)
        names = tuple(problem.names)
        added = names[len(base.names) :]
        earlier = (prior or {}).get(cand.effect)
        own = None
        if earlier is not None and earlier.statistic > 0:
            own = {n: float(v) for n, v in zip(earlier.fit.names, earlier.fit.x, strict=True) if n in added}
        at_base = cols if cand.kind == "effect" and names[: len(base.names)] == base.names else None
        can_stop = not_screened(cand) or cand.kind == "parameter"  # (a parameter's beat: the best sensor's LR)
        stop = cannot_win_after(base.J, statistic, margin, beat) if claim and can_stop else None
        fit = parameter_fit(problem, base, x_added, cand, budget, make_linear, stop)
        fit = fit or candidate_fit(problem, base, x_added, cand, budget, scale, own, at_base, stop)
        J = min(fit.J, base.J)  # the nested model (candidate off) is always available
        lr = statistic(base.J, J)
        k = cand.df if cand.df is not None else len(added) - len(fit.fixed)
        p = float(chi2_sf(lr, k))
        vJ, per = validation_J(names, fit.x) if fit.J < base.J else (base_vJ, base_per)
        better = lowers_validation(vJ, per, base_vJ, base_per, min_gain)
        return Ranked(
            effect=cand.effect, added=added, k=k, J=J, statistic=lr, p_value=p,
            bic_margin=lr - k * math.log(residual_count), validation_J=vJ,
            accepted=bool(claim and p < level and better), fit=fit, seconds=time.perf_counter() - t0,
            kind=cand.kind, validation_per_file=per, fixed=fit.fixed, stopped=fit.stopped,
        )  # fmt: skip

    cols = car() if car is not None and not base.fixed and any(c.kind == "effect" for c in candidates) else None
    out = run_all(one, candidates, prior, on_done or (lambda _n: None), threads)
    out.sort(key=lambda r: -r.statistic)
    return out


def screenable(cand: Candidate) -> bool:
    """An effect whose force is proportional to its strengths: its score statistic at zero strength applies
    (score.screen_effects)."""
    return cand.kind == "effect" and cand.linear and bool(cand.strength)


def not_screened(cand: Candidate) -> bool:
    """An effect whose force is not proportional to its strengths (backlash, a damper's lag): no score statistic at
    zero strength screens it (`screenable`), so its fit may be stopped instead (`cannot_win_after`)."""
    return cand.kind == "effect" and not screenable(cand)


def run_all(one: Callable[[Candidate], Ranked], candidates: list[Candidate], prior: dict[str, Ranked] | None,
            done: Callable[[int], None], threads: int | None = None) -> list[Ranked]:  # fmt: skip
    """one(c) for every candidate, in parallel threads where there are cores (at most `threads`; the longest fits
    first, so that none runs alone at the end: expected_seconds), in the candidates' order; done(n) after each."""
    n = min(available_cores() if threads is None else max(1, threads), len(candidates))
    if n > 1:
        pool = shared_pool("candidates", n)  # threads started once per process (core/pools.py)
        order = sorted(range(len(candidates)), key=lambda i: -expected_seconds(candidates[i], prior))  # longest first
        results: list[Ranked | None] = [None] * len(candidates)
        for k, (j, ranked) in enumerate(as_done(pool, one, [candidates[i] for i in order]), start=1):
            results[order[j]] = ranked
            done(k)
        out = [r for r in results if r is not None]
        release_if_handing_back()  # the threads' arenas keep what their fits freed (a long record's: ~30 MiB)
    else:
        out = []
        for c in candidates:
            out.append(one(c))
            done(len(out))
    return out


def expected_seconds(cand: Candidate, prior: dict[str, Ranked] | None = None) -> float:
    """A guess of how long a candidate's fit takes, to start the longest first (longest-processing-time scheduling
    of the parallel fits; the results do not depend on it): its fit's time in an earlier round, else its starts
    and shape parameters times a nonlinear effect's extra cost (a relative scale)."""
    earlier = (prior or {}).get(cand.effect)
    if earlier is not None and not earlier.screened:
        return earlier.seconds
    return (1 + len(cand.starts)) * (1 + len(cand.shape)) * (1 if cand.linear else 2) * 1e-3


def score_statistics(problem: Problem, x: NDArray, free: NDArray, added: Sequence[int]) -> NDArray:
    """Rao's score statistic of each added unknown (indices `added` into the problem's unknowns, held at their null
    value in x) against the fit at x over the `free` others: (j_c' r)² / |j_c|² with j_c the residuals' derivative
    along the candidate's unknown, less its projection on the fitted unknowns' columns. It is the first-order
    fall of the sum of squared weighted residuals, i.e. of the LR of chi2_statistic, that freeing the unknown
    would bring; every candidate from one forward-difference Jacobian (one batch of free + added + 1 evaluations).
    NaN where the Jacobian is not finite."""
    cols = np.flatnonzero(np.asarray(free, dtype=bool))
    use = np.zeros(len(x), dtype=bool)
    use[cols] = True
    use[list(added)] = True
    Jac, r = forward_jacobian(restricted(problem, x, use), np.asarray(x, dtype=float)[use])
    where = np.cumsum(use) - 1  # column of each unknown in Jac
    out = np.full(len(added), np.nan)
    if not (np.all(np.isfinite(Jac)) and np.all(np.isfinite(r))):
        return out
    Jb = Jac[:, where[cols]]
    for i, c in enumerate(added):
        jc = Jac[:, where[c]]
        jc = jc - Jb @ np.linalg.lstsq(Jb, jc, rcond=None)[0] if Jb.size else jc
        norm = float(jc @ jc)
        out[i] = float(jc @ r) ** 2 / norm if norm > 0 else 0.0
    return out


def undistinguished(ranked: list[Ranked], best: Ranked, alpha: float = ALPHA) -> Ranked | None:
    """The runner-up of the same kind the data cannot tell from `best`, if any: another significant candidate
    whose LR falls short of the best's by less than the critical value of a chi²(k_best) test at the
    per-candidate level (the non-nested comparison of two augmented models: the training data must prefer
    one significantly), unless the validation data prefer the best clearly (its validation J
    DISTINCT_VALIDATION lower). A parameter and an effect are not rivals: parsimony decides (``parsimonious``)."""
    level = alpha / max(len(ranked), 1)
    margin = float(chi2_isf(level, max(best.k, 1)))
    for r in ranked:
        if r is best or r.p_value >= level or r.kind != best.kind:
            continue
        held_out_prefers = best.validation_J < (1.0 - DISTINCT_VALIDATION) * r.validation_J
        if best.statistic - r.statistic < margin and not held_out_prefers:
            return r
    return None


def parsimonious(ranked: list[Ranked], best: Ranked, alpha: float = ALPHA) -> Ranked | None:
    """An accepted known parameter that explains the residual as well as the effect `best` does (its LR short
    of the effect's by less than the critical value of chi²(k_best), or at least PARSIMONY_SHARE of it), the
    strongest such; None if none. (An effect that only mimicked the parameter, a Bouc-Wen element that never
    yields standing in for a stiffer spring, then loses; a real effect is tested again in the next round and
    the backward checks drop the parameter if the effect alone explains it.)"""
    if best.kind != "effect":
        return None
    level = alpha / max(len(ranked), 1)
    margin = float(chi2_isf(level, max(best.k, 1)))
    rivals = [
        r for r in ranked if r.kind == "parameter" and r.accepted
        and (best.statistic - r.statistic < margin or r.statistic >= PARSIMONY_SHARE * best.statistic)
    ]  # fmt: skip
    return max(rivals, key=lambda r: r.statistic, default=None)


def sensor_candidates(checks, channels: Sequence[Channel]) -> dict[str, Candidate]:
    """A `sensor:<channel>:<fault>` candidate for each finding that points to a fault (a swap once per pair): its
    unknowns ``sensor:<channel>:<param>`` with the ranges, start and null value of the fault's correction."""
    views = {c.name: c for c in channels}
    out: dict[str, Candidate] = {}
    for f in checks.problems:
        if not f.fault or f.channel not in views:
            continue
        name = f"sensor:{f.channel}:{f.fault}"
        fault = fault_of(f.fault)
        if fault.pair and f"sensor:{f.fault.partition(':')[2]}:{fault.name}:{f.channel}" in out:
            continue  # the pair's other half names the same swap
        spec = fault.correction(views[f.channel], f)
        unknowns = tuple(f"sensor:{f.channel}:{p}" for p in spec.params)
        out[name] = Candidate(
            name, unknowns, dict(zip(unknowns, spec.limits, strict=True)), dict(zip(unknowns, spec.start, strict=True)),
            kind="sensor", strength=unknowns, null=dict(zip(unknowns, spec.null, strict=True)), linear=False,
            df=spec.df,
        )  # fmt: skip
    return out
