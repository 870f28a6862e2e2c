"""The missing strut force when no library effect explains the residual: a non-parametric estimate.

Per axle (front: corners 1, 2; rear: corners 3, 4) an additive smooth law of the strut deflection d [m] and
velocity v [m/s], F(d, v) = g(d) + h(v) [N], the same at both corners of the axle (each at its own d_i, v_i),
in the kernel's convention (positive resisting positive deflection, like k d; entering as
M qdd + C qd + K q + D' f = B y), with g(0) = h(0) = 0 so the car still starts at rest.

* g and h are cubic B-splines (knots halfway between quantiles and equal spacing of the trajectory's values),
  constrained to vanish at 0, with the integrated squared second derivative as roughness penalty (its null
  space, the straight line through 0, is free: a linear stiffness or damping costs nothing).
* Each basis function, applied at the corners of its axle along the trajectory, is an input force history
  to the LINEAR part (M, C, K) of the fitted car; its responses at the layout's channels (body points, wheel
  hops, deflections, in the task's families, weighted by the task's sigma and laid out like the objective's
  residual: observed samples only, each channel's mean removed when offsets are profiled) come from one exact
  first-order-hold recursion for all basis inputs at once. These are the columns of S; the fitted unknowns'
  own sensitivities (forward differences, one batched simulation) are unpenalised nuisance columns, so what
  the fit already absorbed is not credited to the missing force; when their step moves the trajectory the
  unknowns are updated and re-simulated (Gauss-Newton inside the task's box): the unknowns and the force are
  fitted jointly.
* Penalised weighted least squares min |r - J dx - S theta|² + sum_j lambda_j theta_j' P_j theta_j over the
  kept residual entries, one lambda per function chosen by REML (or GCV, ``criterion``; GCV undersmooths
  more often on pure noise).
* The trajectory the basis is evaluated on is the fitted one corrected by the estimate's own response
  (superposition: for a linear fitted car, data = model + L[F(d_true, v_true)] exactly), re-estimated a few
  times (a fixed-point iteration) so that a force that changes the motion is not evaluated where the
  uncorrected model moves.
* 95 % pointwise bands from the Bayesian posterior sigma² (A'A + P_lambda)^-1, sigma² = max(1, RSS / (R - edf));
  significance: F = ((RSS_0 - RSS_1) / df) / sigma² against F(df, R - edf), RSS_0 the residual with the nuisance
  columns only, edf the trace of the hat matrix H and df = tr(2 H - H H) of the force part (Hastie-Tibshirani's
  reference degrees of freedom, >= edf: a smoothing parameter chosen on the same data makes the plain-edf test
  anti-conservative; on pure noise about 8 % of p-values fall below 0.05, none below 0.001 in 60 seeds).
* When an axle's stiffness (kf, kr) or damping (cf, cr) is among the fitted unknowns, its re-fit and the curve's
  line through 0 are one and the same force: that curve is reported modulo lines (the unknown's re-fit added, then
  the line through 0 projected out on its grid, bands from the joint covariance; its explained power without what
  the unknown's own column absorbs), and compared with the shapes modulo lines too.
* Each estimated curve is compared with the library's shapes by a one-parameter weighted least-squares fit
  (weights: inverse band variance; uncentred R², the curves all pass through 0).

Where the parts live: the P-splines and the penalised least squares in psplines.py, the linear car's responses to
strut forces in linear_response.py, the library's shapes, the resemblance and the candidates it points to in shapes.py;
here the result types and the estimate.

Limitation: when the fitted car has effects of its own (declared or effect unknowns), their states and tangent
stiffness are left out of the superposition: the force's response is that of the linear part only, a first-order
approximation around the fitted trajectory. A missing law that is not additive in d and v (hysteresis, lag,
play) shows only as its best additive projection.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..core.result import Result
from ..identify.objectives import Objective
from ..identify.task import Task
from ..models.fullcar import N_CORNERS, N_DOF
from .linear_response import ForceFit, LinearCar, car_at, fit_matrix, response_gram, responses_blocks
from .psplines import Basis, basis, penalised_fit
from .shapes import Resemblance, points_to, resemblance
from .tails import f_sf

Z95 = 1.959963984540054
AXLES = (("front", (0, 1)), ("rear", (2, 3)))
# The unknown whose change is a line through 0 of each axle's curve (a stiffness over deflection, a damping over
# velocity): when it is fitted, the curve's line is not identifiable apart from it (see estimate_unexplained).
LINE_UNKNOWN = {("front", "deflection"): "kf", ("front", "velocity"): "cf", ("rear", "deflection"): "kr",
                ("rear", "velocity"): "cr"}  # fmt: skip
VARIABLES = ("deflection", "velocity")
UNITS = {"deflection": "m", "velocity": "m/s"}
SIGNIFICANCE = 1e-3  # the F test's level for "the residual holds a strut force" (the loop's alpha)
SIGNIFICANT_Z = 3.0  # a curve is significant where |force| exceeds 3 standard errors somewhere on its grid


# ------------------------------------------------------------------------------------------ results


@dataclass(frozen=True)
class Curve(Result):
    """One estimated function of one axle: g(d) [N] over d [m] or h(v) [N] over v [m/s], with its 95 % band."""

    variable: str  # "deflection" or "velocity"
    grid: NDArray  # (G,) [m] or [m/s]: the observed range
    force: NDArray  # (G,) [N]
    band: NDArray  # (2, G) lower and upper 95 % pointwise limits [N]
    peak_force: float  # max |force| on the grid [N]
    peak_at: float  # where [m] or [m/s]
    z_max: float  # largest |force| / standard error on the grid
    chi2_explained: float  # weighted response power of this curve alone, per kept residual sample
    lam: float  # its smoothing parameter (REML or GCV, relative to the basis' own scale)
    resembles: Resemblance

    @property
    def significant(self) -> bool:
        return bool(self.z_max > SIGNIFICANT_Z)

    def to_json(self) -> dict:
        unit = UNITS[self.variable]
        return {
            f"grid_{unit.replace('/', '_')}": self.grid.tolist(),
            "force_N": self.force.tolist(),
            "band95_N": [self.band[0].tolist(), self.band[1].tolist()],
            "peak_force_N": self.peak_force,
            f"peak_at_{unit.replace('/', '_')}": self.peak_at,
            "z_max": self.z_max,
            "significant": self.significant,
            "chi2_explained": self.chi2_explained,
            "lambda": self.lam,
            "resembles": self.resembles.to_json(),
        }


@dataclass(frozen=True)
class AxleEstimate(Result):
    """The missing force law of one axle, F = g(d) + h(v)."""

    axle: str  # "front" or "rear"
    g: Curve  # over deflection
    h: Curve  # over velocity

    @property
    def d_grid(self) -> NDArray:
        return self.g.grid

    @property
    def g_band(self) -> NDArray:
        return self.g.band

    @property
    def v_grid(self) -> NDArray:
        return self.h.grid

    @property
    def h_band(self) -> NDArray:
        return self.h.band

    @property
    def dominant(self) -> Curve:
        """The curve that explains more of the residual."""
        return self.g if self.g.chi2_explained >= self.h.chi2_explained else self.h

    @property
    def peak_force_N(self) -> float:
        return max(self.g.peak_force, self.h.peak_force)

    @property
    def acts_on(self) -> str:
        """'deflection' or 'velocity': where the larger peak force acts."""
        return self.g.variable if self.g.peak_force >= self.h.peak_force else self.h.variable

    def to_json(self) -> dict:
        big = self.g if self.acts_on == "deflection" else self.h
        return {
            "deflection": self.g.to_json(),
            "velocity": self.h.to_json(),
            "peak_force_N": self.peak_force_N,
            "acts_on": self.acts_on,
            "peak_at": big.peak_at,
        }


@dataclass(frozen=True)
class Unexplained(Result):
    """The non-parametric estimate of the missing strut force and how much of the residual it explains."""

    front: AxleEstimate
    rear: AxleEstimate
    chi2_before: float  # kept weighted residual power per sample of the fitted model
    chi2_after: float  # after subtracting the estimate's response (and the unknowns' linear re-fit)
    edf: float  # effective degrees of freedom of the force estimate (hat trace minus the nuisance's)
    edf_total: float  # hat trace including the nuisance columns
    df_test: float  # the test's degrees of freedom, tr(2 H - H H) of the force part (>= edf: selection of lambda)
    F: float  # ((RSS_0 - RSS_1) / df_test) / sigma2
    p_value: float  # of F under F(df_test, R - edf_total): small = the residual holds a strut force
    sigma2: float  # residual variance used for the bands (>= 1, the noise's own)
    samples: int  # R: kept residual entries
    iterations: int  # trajectory corrections made
    dx: NDArray  # re-fit of the unknowns that comes with the estimate (from x)
    names: tuple[str, ...]
    x: NDArray | None = None  # the fit the estimate started from (names = x; x + dx: the unknowns beside the force)
    dx_ci: NDArray | None = None  # 95 % half-widths of the unknowns fitted beside the force (posterior covariance)

    @property
    def unknowns(self) -> NDArray | None:
        """The unknowns fitted jointly with the non-parametric force (None when they were not re-fitted)."""
        return None if self.x is None or not self.dx.size else self.x + self.dx

    @property
    def axles(self) -> dict[str, AxleEstimate]:
        return {"front": self.front, "rear": self.rear}

    @property
    def dominant(self) -> tuple[str, Curve]:
        """(axle, curve) that explains the most residual power."""
        pairs = [(a.axle, c) for a in (self.front, self.rear) for c in (a.g, a.h)]
        return max(pairs, key=lambda p: p[1].chi2_explained)

    @property
    def peak_force_N(self) -> float:
        return self.dominant[1].peak_force

    @property
    def acts_on(self) -> dict:
        axle, c = self.dominant
        return {"axle": axle, "variable": c.variable, "at": c.peak_at, "unit": UNITS[c.variable]}

    @property
    def resembles(self) -> str:
        """The library shape closest to the curve that explains the most residual."""
        return self.dominant[1].resembles.best

    @property
    def points_to(self) -> tuple[str, ...]:
        """The library effects and known parameters whose shapes the significant curves resemble, best first."""
        return points_to(self)

    @property
    def significant(self) -> bool:
        """Does the residual hold a strut force (the F test at SIGNIFICANCE, and a curve above its noise)?"""
        return bool(self.p_value < SIGNIFICANCE and any(c.significant for a in self.axles.values() for c in (a.g, a.h)))

    def summary(self) -> str:
        """One line: how large the missing force is, where it acts, what it looks like."""
        where = self.acts_on
        at = f"{1e3 * where['at']:.3g} mm" if where["variable"] == "deflection" else f"{where['at']:.3g} m/s"
        r2 = self.dominant[1].resembles.r2.get(self.resembles, float("nan"))
        terms = self.points_to
        pointed = f"; of the library's terms its shape points to {', '.join(terms)}" if terms else ""
        return (
            f"peaks at {self.peak_force_N:.3g} N on the {where['axle']} axle over {where['variable']} (at {at}) "
            f"and resembles {self.resembles} (R² {r2:.2f}){pointed}"
        )

    def to_json(self) -> dict:
        return {
            "axles": {"front": self.front.to_json(), "rear": self.rear.to_json()},
            "chi2_before": self.chi2_before,
            "chi2_after": self.chi2_after,
            "edf": self.edf,
            "edf_total": self.edf_total,
            "df_test": self.df_test,
            "F": self.F,
            "p_value": self.p_value,
            "sigma2": self.sigma2,
            "samples": self.samples,
            "iterations": self.iterations,
            "refit_dx": dict(zip(self.names, map(float, self.dx), strict=True)),
            "refit_ci95_halfwidth": None
            if self.dx_ci is None or not self.dx.size
            else dict(zip(self.names, map(float, self.dx_ci), strict=True)),
            "peak_force_N": self.peak_force_N,
            "acts_on": self.acts_on,
            "resembles": self.resembles,
            "points_to": list(self.points_to),
        }


# ------------------------------------------------------------------------------------------ the estimate


def _trajectories(task: Task, names: tuple[str, ...], X: NDArray):
    """Simulate the batch X (P, D): the layout's channels (family -> (P, n, k)) and each corner's deflection and
    velocity (P, n, 4). A record the experiment simulates in time blocks is read a block at a time (the same
    numbers; its whole trajectories are not held)."""
    exp = task.experiment
    values = {n: X[:, j] for j, n in enumerate(names)}
    with np.errstate(all="ignore"):
        G = np.broadcast_to(exp.matrices(values).G, (X.shape[0], N_CORNERS, 3))
        Gt = np.swapaxes(G, -1, -2)[:, None, :, :]
        if not exp.blocked(values):
            resp = exp.simulate(values)
            return exp.read(resp), *_struts(resp, Gt)
        n = exp.t.size
        channels: dict[str, NDArray] = {}
        d, v = np.empty((X.shape[0], n, N_CORNERS)), np.empty((X.shape[0], n, N_CORNERS))
        for k0, resp in exp.simulate_blocks(values):
            b = resp.q.shape[-2]
            for family, y in exp.read(resp).items():
                channels.setdefault(family, np.empty(y.shape[:-2] + (n, y.shape[-1])))[..., k0 : k0 + b, :] = y
            d[:, k0 : k0 + b], v[:, k0 : k0 + b] = _struts(resp, Gt)
    return channels, d, v


def _struts(resp, Gt: NDArray) -> tuple[NDArray, NDArray]:
    """Each corner's strut deflection and velocity (P, n, 4) of a response (P, n, .), Gt (P, 1, 3, 4) its body rows."""
    d = (resp.q[..., None, :3] @ Gt)[..., 0, :] - resp.q[..., 3:]
    v = (resp.qd[..., None, :3] @ Gt)[..., 0, :] - resp.qd[..., 3:]
    return d, v


@dataclass(frozen=True)
class _Linearisation:
    """The fitted car at some values of its unknowns: the weighted residual (R_all,), the model's sensitivities to
    the unknowns over sigma (R_all, p), each corner's strut deflection and velocity (n, 4) and their sensitivities
    (p, n, 4), and its linear part."""

    r: NDArray
    Jm: NDArray
    d: NDArray
    v: NDArray
    dd: NDArray
    dv: NDArray
    car: LinearCar


@dataclass(frozen=True)
class _FittedCar:
    """What the estimate holds fixed: the task (one run) with its objective on the reference, the fitted unknowns'
    names and the task's box for them, and whether they are re-fitted with the force (nuisance columns)."""

    task: Task
    names: tuple[str, ...]
    objective: Objective
    sigma: dict[str, NDArray]  # family -> (k,) the task's noise sigma of the family's channels
    lo: NDArray
    hi: NDArray
    nuisance: bool

    @classmethod
    def of(cls, task: Task, reference: dict[str, NDArray], names: tuple[str, ...], nuisance: bool) -> _FittedCar:
        """The fitted car `names` of `task` against `reference` (family -> (n, k)); `nuisance`: re-fit the unknowns."""
        objective = task.objective(reference)
        sigma = {f: np.asarray(task.sigma[f], dtype=float) for f in reference}
        lo = np.array([task.lower[task.names.index(m)] if m in task.names else -np.inf for m in names])
        hi = np.array([task.upper[task.names.index(m)] if m in task.names else np.inf for m in names])
        return cls(task, names, objective, sigma, lo, hi, bool(nuisance and names))

    def linearise(self, at: NDArray) -> _Linearisation:
        """Residual, trajectories and the unknowns' sensitivities at `at` (one batched simulation)."""
        exp, lo, hi = self.task.experiment, self.lo, self.hi
        n = exp.t.size
        steps = np.zeros(0)
        if self.nuisance:
            width = np.where(np.isfinite(hi - lo), hi - lo, np.abs(at))
            h = 1e-6 * np.maximum(np.abs(at), np.maximum(1e-3 * width, 1e-9))
            steps = np.where(at + h <= hi, h, -h)
        X = np.vstack([at[None, :], at[None, :] + np.diag(steps)]) if steps.size else at[None, :]
        channels, d_all, v_all = _trajectories(self.task, self.names, X)
        res = np.asarray(self.objective.residuals(channels), dtype=float)  # (P, R_all)
        del channels
        if not np.all(np.isfinite(res[0])):
            raise ValueError("the fitted model's residual is not finite")
        if steps.size:
            Jm = (-(res[1:] - res[0]) / steps[:, None]).T  # d model / dx / sigma
            dd = (d_all[1:] - d_all[0]) / steps[:, None, None]
            dv = (v_all[1:] - v_all[0]) / steps[:, None, None]
        else:
            Jm, dd, dv = np.zeros((res.shape[1], 0)), np.zeros((0, n, 4)), np.zeros((0, n, 4))
        car = car_at(exp, {m: at[j] for j, m in enumerate(self.names)}, exp.dt)
        return _Linearisation(res[0], Jm, d_all[0], v_all[0], dd, dv, car)

    def force_columns(self, d: NDArray, v: NDArray, n_knots: int) -> tuple[tuple[Basis, ...], NDArray]:
        """The basis of each function (front g, front h, rear g, rear h) on the trajectory d, v (n, 4), its columns
        applied as input forces at the corners of its axle: the bases and the input histories U (n, 4, K). (Their
        weighted responses, laid out like the residual, are summed into the fit's normal equations without being
        held, `response_gram`; the car's states driven by U are made a block of time at a time and not kept.)"""
        n = self.task.experiment.t.size
        each = [(basis(traj[:, corners], n_knots), traj, corners) for _axle, corners in AXLES for traj in (d, v)]
        U = np.zeros((n, N_CORNERS, sum(b.size for b, _, _ in each)))  # (n, 4, K), each basis into its columns
        k0 = 0
        for b, traj, corners in each:
            for c in corners:
                U[:, c, k0 : k0 + b.size] = b(traj[:, c])
            k0 += b.size
        return tuple(b for b, _, _ in each), U


def trajectory_shift(car: LinearCar, U: NDArray, theta: NDArray) -> tuple[NDArray, NDArray]:
    """The strut deflections and velocities (n, 4) that the force U theta drives the linear car to (its response to
    the one input history U (n, 4, K) @ theta (K,), through the struts' D), a block at a time. The car is linear: the
    same as combining the K basis inputs' responses by theta (to round-off), at 1/K of the recursion's work."""
    n = U.shape[0]
    new_d, new_v = np.empty((n, N_CORNERS)), np.empty((n, N_CORNERS))
    for k0, s in responses_blocks(car, (U @ theta)[:, :, None]):
        b = s.shape[0]
        new_d[k0 : k0 + b] = s[:, :N_DOF, 0] @ car.D.T
        new_v[k0 : k0 + b] = s[:, N_DOF:, 0] @ car.D.T
    return new_d, new_v


def _fit_without_force(Jk: NDArray, rk0: NDArray) -> tuple[float, float]:
    """RSS and degrees of freedom of the fit without the force on the kept residual rk0: the unknowns' linearised
    re-fit (columns Jk) at x (x itself when it is the fit's optimum)."""
    p = Jk.shape[1]
    if p:
        JtJ = Jk.T @ Jk + 1e-12 * np.trace(Jk.T @ Jk) * np.eye(p)
        c0 = np.linalg.solve(JtJ, Jk.T @ rk0)
        rss0 = min(float(np.sum((rk0 - Jk @ c0) ** 2)), float(rk0 @ rk0))
        edf0 = float(np.trace(np.linalg.solve(JtJ, Jk.T @ Jk)))
    else:
        rss0, edf0 = float(rk0 @ rk0), 0.0
    return rss0, edf0


def _fit_force(
    fitted: _FittedCar, lin: _Linearisation, d: NDArray, v: NDArray, keep: NDArray, n_knots: int, criterion: str
) -> ForceFit:
    """The force on the trajectory d, v jointly with the unknowns' linear re-fit, over the kept residual entries,
    one smoothing parameter per function (REML or GCV)."""
    rk, Jk = lin.r[keep], lin.Jm[keep]
    p = Jk.shape[1]
    bases, U = fitted.force_columns(d, v, n_knots)
    obj, car, sigma = fitted.objective, lin.car, fitted.sigma
    if rk.size * (p + U.shape[2]) * 8 > FIT_GRAM_BYTES:  # A = [Jk | S[keep]] summed, not held
        A, (AtA, Atr) = None, response_gram(obj, car, U, sigma, keep, Jk, rk)
    else:
        A = fit_matrix(obj, car, U, sigma, keep, Jk)  # [Jk | S[keep]], S's kept rows only
        AtA, Atr = A.T @ A, A.T @ rk
    blocks, k0 = [], p
    for b in bases:
        blocks.append((slice(k0, k0 + b.size), b.P))
        k0 += b.size
    sol = penalised_fit(AtA, Atr, float(rk @ rk), int(keep.sum()), blocks, criterion)
    return ForceFit(d, v, bases, U, A, AtA, Atr, rk, sol, p)


FIT_GRAM_BYTES = 12 * 2**20  # a fit matrix A above this (a long record's window: 15 MB at 5000 samples) is reduced
# to A'A, A'r as it is made (linear_response.response_gram); smaller ones are held, their numbers as before: the
# smoothing parameters' REML optimum moves with the sums' round-off (by up to 1e-3 of its edf)


@dataclass(frozen=True)
class _Converged:
    """The fixed-point iteration's end: the last fit, the unknowns' total re-fit from x, the corrections made; and
    at x, the kept residual's chi² per sample and the fit without the force (its RSS and degrees of freedom)."""

    fit: ForceFit
    dx: NDArray
    corrections: int
    chi2_before: float
    rss0: float
    edf0: float


def _iterate(
    fitted: _FittedCar, lin: _Linearisation, x: NDArray, keep: NDArray, n_knots: int, iterations: int, criterion: str
) -> _Converged:
    """Fit the force on the fitted trajectory corrected by the estimate's own response and the unknowns' shift
    (superposition), re-estimate on the corrected trajectory until it stops moving (at most `iterations` times);
    when the unknowns' step moves the trajectory, a Gauss-Newton step: re-simulate there. `lin`: the linearisation at
    x, this function's to let go (the caller holds no other reference)."""
    rk0 = lin.r[keep]
    chi2_before = float(np.mean(rk0**2))
    rss0, edf0 = _fit_without_force(lin.Jm[keep], rk0)
    del rk0
    x_cur = x.copy()
    corr_d = np.zeros_like(lin.d)
    corr_v = np.zeros_like(lin.v)
    done = 0
    for it in range(max(0, iterations) + 1):
        d, v = lin.d + corr_d, lin.v + corr_v
        fit = None  # the last fit's columns freed before the next are made (a long window's are tens of MB)
        fit = _fit_force(fitted, lin, d, v, keep, n_knots, criterion)
        theta, dx = fit.theta, fit.dx
        # the trajectory of the corrected model: fitted + the unknowns' shift + the estimate's own response
        new_d, new_v = trajectory_shift(lin.car, fit.U, theta)
        shift_d, shift_v = np.tensordot(dx, lin.dd, axes=1), np.tensordot(dx, lin.dv, axes=1)
        change = max(float(np.max(np.abs(new_d + shift_d - corr_d)) / np.ptp(d)),
                     float(np.max(np.abs(new_v + shift_v - corr_v)) / np.ptp(v)))  # fmt: skip
        if it == iterations or change < 1e-3:
            break
        done += 1
        corr_d, corr_v = new_d, new_v
        moved = float(np.max(np.abs(shift_d)) / np.ptp(d)) > 1e-4 or float(np.max(np.abs(shift_v)) / np.ptp(v)) > 1e-4
        if fit.p and moved:  # a Gauss-Newton step of the unknowns: re-simulate there
            x_cur = np.clip(x_cur + dx, fitted.lo, fitted.hi)
            fit = lin = None  # this fit's columns and the last linearisation freed before the car is simulated again
            lin = fitted.linearise(x_cur)
    return _Converged(fit, np.clip(x_cur + fit.dx, fitted.lo, fitted.hi) - x, done, chi2_before, rss0, edf0)


@dataclass(frozen=True)
class _FTest:
    """Does the residual hold a strut force: the fit with the force against the fit without it."""

    rss1: float  # kept residual power with the force
    edf_force: float
    df_test: float
    sigma2: float
    F: float
    p_value: float


def _f_test(fit: ForceFit, rss0: float, edf0: float, R: int) -> _FTest:
    """The F test of the force against the fit without it (RSS rss0 over edf0 degrees of freedom), on R entries."""
    sol = fit.sol
    rss1 = fit.rss(sol.coef)
    edf_force = max(sol.edf - edf0, 1e-9)
    df_test = max(sol.edf2 - edf0, edf_force)
    dof = max(R - sol.edf, 1.0)
    sigma2 = max(1.0, rss1 / dof)
    F = max(rss0 - rss1, 0.0) / df_test / sigma2
    p_value = float(f_sf(F, df_test, dof))
    return _FTest(rss1, edf_force, df_test, sigma2, F, p_value)


def _curve(
    variable: str, grid: NDArray, Bg: NDArray, sl: slice, line: int | None, fit: ForceFit, V: NDArray, lam: float
) -> Curve:
    """One function's curve over `grid` (Bg its basis there, sl its columns) with its 95 % band (covariance V) and
    resemblance; `line`: the column of the unknown whose re-fit is the curve's line through 0 (the curve is then
    reported modulo lines), None when that unknown is not fitted."""
    coef = fit.sol.coef
    if line is not None:  # its line and the unknown's re-fit are one: the curve modulo lines
        rows = np.zeros((grid.size, coef.size))
        rows[:, sl], rows[:, line] = Bg, grid
        rows -= np.outer(grid, grid @ rows) / float(grid @ grid)
        f = rows @ coef
        se = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", rows, V, rows), 0.0))
    else:
        f = Bg @ coef[sl]
        se = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", Bg, V[sl, sl], Bg), 0.0))
    i_peak = int(np.argmax(np.abs(f)))
    z = np.abs(f) / np.maximum(se, 1e-300)
    return Curve(
        variable=variable, grid=grid, force=f, band=np.vstack([f - Z95 * se, f + Z95 * se]),
        peak_force=float(abs(f[i_peak])), peak_at=float(grid[i_peak]),
        z_max=float(np.max(np.where(se > 0, z, 0.0))), chi2_explained=fit.explained(sl, line),
        lam=float(lam), resembles=resemblance(variable, grid, f, se, free_line=line is not None),
    )  # fmt: skip


def _axle_estimates(fit: ForceFit, names: tuple[str, ...], sigma2: float, grid_points: int) -> list[AxleEstimate]:
    """Each axle's curves over the observed range of its trajectory, bands from the posterior covariance."""
    V = sigma2 * fit.sol.cov
    axles = []
    j, k0 = 0, fit.p
    for axle, corners in AXLES:
        curves = []
        for var, traj in (("deflection", fit.d), ("velocity", fit.v)):
            b = fit.bases[j]
            sl = slice(k0, k0 + b.size)
            grid = np.linspace(float(np.min(traj[:, corners])), float(np.max(traj[:, corners])), grid_points)
            Bg = b(grid)
            own = LINE_UNKNOWN[(axle, var)]
            line = names.index(own) if own in names[: fit.p] else None
            curves.append(_curve(var, grid, Bg, sl, line, fit, V, fit.sol.lam[j]))
            j += 1
            k0 += b.size
        axles.append(AxleEstimate(axle, curves[0], curves[1]))
    return axles


def estimate_unexplained(
    task: Task,
    reference: dict[str, NDArray],
    names: Sequence[str],
    x: NDArray,
    keep: NDArray | None = None,
    *,
    n_knots: int = 10,
    iterations: int = 6,
    nuisance: bool = True,
    grid_points: int = 41,
    criterion: str = "reml",
) -> Unexplained:
    """Estimate the strut force F(d, v) = g(d) + h(v) [N] per axle that the car `names` = x (fitted on
    `task`, one run) misses in `reference` (family -> (n, k) [m/s², m], the layout's channels); `keep` masks the
    residual entries the fit used (the objective's layout: family, time, channel; observed entries only). With
    `nuisance` the unknowns are re-fitted jointly with the force (Gauss-Newton steps inside the task's box), else
    they stay at x. At most `iterations` trajectory corrections (and re-simulations when the unknowns move).
    See the module doc."""
    names = tuple(names)
    x = np.asarray(x, dtype=float).ravel()
    if x.size != len(names):
        raise ValueError(f"{len(names)} names but {x.size} values")
    fitted = _FittedCar.of(task, reference, names, nuisance)
    R_all = fitted.objective.size
    keep = np.ones(R_all, dtype=bool) if keep is None else np.asarray(keep, dtype=bool)
    if keep.shape != (R_all,):
        raise ValueError(f"keep must have {R_all} entries (family, time, channel), got {keep.shape}")
    R = int(keep.sum())
    # the first linearisation handed over, not held here: _iterate lets it go when it linearises again
    end = _iterate(fitted, fitted.linearise(x), x, keep, n_knots, iterations, criterion)
    test = _f_test(end.fit, end.rss0, end.edf0, R)
    axles = _axle_estimates(end.fit, names, test.sigma2, grid_points)
    p = end.fit.p
    dx_ci = Z95 * np.sqrt(np.maximum(np.diag(test.sigma2 * end.fit.sol.cov)[:p], 0.0))
    return Unexplained(
        front=axles[0], rear=axles[1], chi2_before=end.chi2_before, chi2_after=test.rss1 / R,
        edf=float(test.edf_force), edf_total=float(end.fit.sol.edf), df_test=float(test.df_test), F=float(test.F),
        p_value=test.p_value, sigma2=float(test.sigma2), samples=R, iterations=end.corrections, dx=end.dx, names=names,
        x=x, dx_ci=dx_ci,
    )  # fmt: skip
