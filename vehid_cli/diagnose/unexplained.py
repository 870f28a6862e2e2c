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

Limitation: when the fitted car has effects of its own (declared or effect unknowns), their states and tangent
stiffness are left out of the superposition: the force's response is that of the linear part only, a first-order
approximation around the fitted trajectory. A missing law that is not additive in d and v (hysteresis, lag,
play) shows only as its best additive projection.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import scipy.optimize
from numpy.typing import NDArray
from scipy import stats
from scipy.interpolate import BSpline

from ..models.fullcar import N_CORNERS, N_DOF
from ..sim.modal import foh_discretisation
from ..sim.nonlinear import fullcar_struts

Z95 = 1.959963984540054
ALPHA = 1e-3  # significance level below which candidate_order reorders (attribution's family-wise level)
AXLES = (("front", (0, 1)), ("rear", (2, 3)))
# The unknown whose change is a line through 0 of each axle's curve (a stiffness over deflection, a damping over
# velocity): when it is fitted, the curve's line is not identifiable apart from it (see estimate_unexplained).
LINE_UNKNOWN = {("front", "deflection"): "kf", ("front", "velocity"): "cf", ("rear", "deflection"): "kr",
                ("rear", "velocity"): "cr"}  # fmt: skip
VARIABLES = ("deflection", "velocity")
UNITS = {"deflection": "m", "velocity": "m/s"}
SIGNIFICANCE = 1e-3  # the F test's level for "the residual holds a strut force" (the loop's alpha)
SIGNIFICANT_Z = 3.0  # a curve is significant where |force| exceeds 3 standard errors somewhere on its grid
LOG_LAMBDA = (-7.0, 8.0)  # search range of log10 lambda relative to the basis' own scale
GAS_L, GAS_KAPPA = 0.1, 1.4  # the library's gas_spring defaults [m], [-]
COULOMB_EPS, ASYM_EPS = 0.01, 0.02  # the library's coulomb_friction / asymmetric_damping v_eps [m/s]

# Shape -> the library effects (and parameter candidates) it points to, with an affinity in [0, 1].
# "{axle}" is filled with f / r. Secondary entries: a lagged damper adds stiffness, saturated Bouc-Wen
# hysteresis looks like friction (and like stiffness at small amplitude), a bump stop like stiffening.
SHAPE_EFFECTS: dict[str, tuple[tuple[str, float], ...]] = {
    "linear_stiffness": (("parameter:k{axle}", 1.0), ("damper_lag", 0.5), ("hysteresis", 0.4)),
    "progressive_spring": (("progressive_spring", 1.0), ("gas_spring", 0.5), ("backlash", 0.3)),
    "gas_spring": (("gas_spring", 1.0), ("progressive_spring", 0.5)),
    "dead_band": (("backlash", 1.0), ("progressive_spring", 0.5)),
    "linear_damping": (("parameter:c{axle}", 1.0), ("damper_lag", 0.3), ("tyre_damping", 0.3)),
    "coulomb_friction": (("coulomb_friction", 1.0), ("hysteresis", 0.7)),
    "asymmetric_damping": (("asymmetric_damping", 1.0),),
    "one_sided_damping": (("asymmetric_damping", 1.0),),
    "quadratic_damping": (("asymmetric_damping", 0.6),),
    "sqrt_damper": (("coulomb_friction", 0.7), ("hysteresis", 0.4)),
}
SHAPES = {
    "deflection": ("linear_stiffness", "progressive_spring", "gas_spring", "dead_band"),
    "velocity": (
        "linear_damping", "coulomb_friction", "asymmetric_damping", "one_sided_damping", "quadratic_damping",
        "sqrt_damper",
    ),
}  # fmt: skip


# ------------------------------------------------------------------------------------------ results


@dataclass(frozen=True)
class Resemblance:
    """How well each library shape, scaled by one least-squares amplitude, matches an estimated curve."""

    best: str
    r2: dict[str, float]  # uncentred weighted R² per shape (0 when the amplitude must have the other sign)
    amplitude: dict[str, float]  # fitted amplitude per shape [N per unit of the shape]
    detail: dict[str, str]  # how a profiled shape was chosen (dead band width, one-sided direction)

    def to_json(self) -> dict:
        return {"best": self.best, "r2": dict(self.r2), "amplitude": dict(self.amplitude), "detail": dict(self.detail)}


@dataclass(frozen=True)
class Curve:
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
class AxleEstimate:
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
class Unexplained:
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
    def significant(self) -> bool:
        """Does the residual hold a strut force (the F test at SIGNIFICANCE, and a curve above its noise)?"""
        return bool(self.p_value < SIGNIFICANCE and any(c.significant for a in self.axles.values() for c in (a.g, a.h)))

    def summary(self) -> str:
        """One line: how large the missing force is, where it acts, what it looks like."""
        where = self.acts_on
        at = f"{1e3 * where['at']:.3g} mm" if where["variable"] == "deflection" else f"{where['at']:.3g} m/s"
        r2 = self.dominant[1].resembles.r2.get(self.resembles, float("nan"))
        return (
            f"peaks at {self.peak_force_N:.3g} N on the {where['axle']} axle over {where['variable']} (at {at}) "
            f"and resembles {self.resembles} (R² {r2:.2f})"
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
            "peak_force_N": self.peak_force_N,
            "acts_on": self.acts_on,
            "resembles": self.resembles,
        }


# ------------------------------------------------------------------------------------------ splines


@dataclass(frozen=True)
class _Basis:
    """A cubic B-spline basis on [t[3], t[-4]] constrained to vanish at 0 (columns B Z), with its penalty."""

    t: NDArray
    Z: NDArray  # (nb, nb - 1)
    P: NDArray  # (nb - 1, nb - 1): integral of (second derivative)² in the constrained coefficients

    @property
    def size(self) -> int:
        return self.Z.shape[1]

    def __call__(self, x: NDArray) -> NDArray:
        """(len(x), size) constrained basis at x (clipped into the knot span)."""
        lo, hi = self.t[3], self.t[-4]
        xc = np.clip(np.asarray(x, dtype=float).ravel(), lo, hi)
        B = BSpline.design_matrix(xc, self.t, 3).toarray()
        return B @ self.Z


def _basis(values: NDArray, n_knots: int) -> _Basis:
    """Knots halfway between the values' quantiles and equal spacing over their range (dense where the data
    are, still reaching the sparse extremes); 0 kept inside the span."""
    v = np.asarray(values, dtype=float).ravel()
    lo, hi = min(float(np.min(v)), 0.0), max(float(np.max(v)), 0.0)
    span = hi - lo
    if not span > 0:
        raise ValueError("the strut does not move: no force law can be estimated from this trajectory")
    lo, hi = lo - 1e-6 * span, hi + 1e-6 * span
    p = np.linspace(0.0, 1.0, n_knots + 2)[1:-1]
    inner = 0.5 * (np.quantile(v, p) + lo + p * (hi - lo))
    inner = np.unique(inner[(inner > lo) & (inner < hi)])
    t = np.r_[[lo] * 4, inner, [hi] * 4]
    nb = t.size - 4
    # penalty: exact 2-point Gauss quadrature per knot interval (B'' is linear on each)
    edges = np.unique(t)
    a, b = edges[:-1], edges[1:]
    g = np.array([-1.0, 1.0]) / math.sqrt(3.0)
    xq = (0.5 * (a + b)[:, None] + 0.5 * (b - a)[:, None] * g[None, :]).ravel()
    wq = np.repeat(0.5 * (b - a), 2)
    d2 = BSpline(t, np.eye(nb), 3).derivative(2)(xq)  # (nq, nb)
    P = d2.T @ (wq[:, None] * d2)
    c = BSpline.design_matrix(np.array([0.0]), t, 3).toarray()[0]
    Q, _ = np.linalg.qr(c[:, None], mode="complete")
    Z = Q[:, 1:]
    return _Basis(t=t, Z=Z, P=Z.T @ P @ Z)


# ------------------------------------------------------------------------------------------ the car's response


@dataclass(frozen=True)
class _LinearCar:
    """The fitted car's linear part, discretised for strut-force inputs u (4 corners) with a first-order hold,
    with the output rows of the layout's channels."""

    Phi: NDArray
    G1: NDArray
    G2: NDArray
    out_s: dict[str, NDArray]  # family -> (k, 14): the family's channels from the state
    out_u: dict[str, NDArray]  # family -> (k, 4): direct feed-through of the strut forces
    D: NDArray  # (4, 7) strut deflection from q


def _output_rows(layout, family: str, points: NDArray) -> tuple[NDArray, NDArray]:
    """(k, 3) body rows and (k, 4) wheel rows giving each channel of `family` from the body coordinates
    (x_b, phi, theta) and the wheel hops (or their accelerations): a body sensor reads its point's row of `points`
    (Layout.points, (nb, 3)), a wheel sensor its wheel, a deflection sensor the point above its corner minus the
    wheel."""
    index = {pt: i for i, pt in enumerate(layout._points)}
    sensors = layout.of(family)
    body = np.zeros((len(sensors), 3))
    wheel = np.zeros((len(sensors), N_CORNERS))
    for j, s in enumerate(sensors):
        if s.point is not None:
            body[j] = points[index[s.point]]
        if s.kind.startswith("wheel"):
            wheel[j, s.corner - 1] = 1.0
        elif s.kind == "deflection":
            wheel[j, s.corner - 1] = -1.0
    return body, wheel


def _linear_car(mats, dt: float, layout, points: NDArray) -> _LinearCar:
    """The car `mats` (one set of matrices) discretised at dt [s], its outputs the channels of `layout` with body
    point rows `points` (Layout.points of the car, (nb, 3); the paper's layout: the rows of G)."""
    A, _ = mats.state_space()
    D = fullcar_struts(mats)
    Minv = np.linalg.inv(mats.M)
    Bf = np.zeros((2 * N_DOF, N_CORNERS))
    Bf[N_DOF:, :] = -Minv @ D.T  # generalised force -D' f
    Phi, G1, G2 = foh_discretisation(A, Bf, dt)
    out_s, out_u = {}, {}
    for family in layout.families:
        body, wheel = _output_rows(layout, family, points)
        if family == "acc":  # accelerations: the rows of qdd = A_qdd s + B_qdd f
            out_s[family] = body @ A[N_DOF : N_DOF + 3, :] + wheel @ A[N_DOF + 3 :, :]
            out_u[family] = body @ Bf[N_DOF : N_DOF + 3, :] + wheel @ Bf[N_DOF + 3 :, :]
        else:  # displacements: the rows of q
            rows = np.zeros((body.shape[0], 2 * N_DOF))
            rows[:, :3], rows[:, 3:N_DOF] = body, wheel
            out_s[family] = rows
            out_u[family] = np.zeros((body.shape[0], N_CORNERS))
    return _LinearCar(Phi, G1, G2, out_s, out_u, D)


def _car_at(exp, values: dict[str, float], dt: float) -> _LinearCar:
    """The linear car `values` at dt [s] with the outputs of the experiment's layout."""
    layout = exp.layout
    return _linear_car(exp.matrices(values), dt, layout, layout.points(exp.parameters(values)))


def _channel_columns(objective, family: str, car: _LinearCar, s: NDArray, U: NDArray, sigma: NDArray) -> NDArray:
    """The weighted residual entries of `family` (the objective's layout: time-major, observed entries only) that
    the K input histories U (n, 4, K) with states s (n, 14, K) explain, (R_family, K): the channels' responses over
    sigma, without what the profiled offsets absorb."""
    Y = (car.out_s[family] @ s + car.out_u[family] @ U) / sigma[None, :, None]  # (n, k, K)
    if objective.offsets:
        objective.project(family, np.moveaxis(Y, -1, 0))  # in place, through the (K, n, k) view
    Y = Y.reshape(Y.shape[0] * Y.shape[1], -1)
    rows = objective.entries(family)
    return Y if rows is None else Y[rows]


def _responses(car: _LinearCar, U: NDArray) -> NDArray:
    """States (n, 14, K) of the car at rest driven by K strut-force histories U (n, 4, K), one recursion."""
    n = U.shape[0]
    s = np.empty((n, 2 * N_DOF, U.shape[2]))
    s[0] = 0.0
    np.matmul(car.G1, U[:-1], out=s[1:])
    s[1:] += car.G2 @ np.diff(U, axis=0)
    Phi = car.Phi
    for k in range(n - 1):
        s[k + 1] += Phi @ s[k]
    return s


# ------------------------------------------------------------------------------------------ penalised fit


@dataclass(frozen=True)
class _Solution:
    coef: NDArray
    cov: NDArray  # (A'A + P_lambda)^-1 in the original column units
    lam: NDArray  # per penalised block
    edf: float  # trace of the hat matrix
    rss: float
    edf2: float  # tr(2 H - H H): the reference degrees of freedom of the test


def _solve(
    AtA: NDArray, Atr: NDArray, rtr: float, R: int, blocks: list[tuple[slice, NDArray]], criterion: str = "reml"
) -> _Solution:
    """min |r - A c|² + sum_j lam_j c_j' P_j c_j, the lam_j by REML (default) or GCV.

    REML: the restricted likelihood with the scale profiled out, (R - M0) log(RSS + c' P_lam c) + log|H|
    - sum_j rank_j log lam_j, H = A'A + P_lam, M0 the penalty's null-space dimension; GCV: R RSS / (R - edf)².
    """
    scale = np.sqrt(np.maximum(np.diag(AtA), 1e-300))
    As = AtA / np.outer(scale, scale)
    bs = Atr / scale
    m = As.shape[0]
    Ps, ranks = [], []
    for sl, P in blocks:
        Pj = np.zeros((m, m))
        Pj[sl, sl] = P / np.outer(scale[sl], scale[sl])
        Pj /= max(np.trace(Pj) / (sl.stop - sl.start), 1e-300)  # lam = 1: penalty on the scale of the data term
        ev = np.linalg.eigvalsh(Pj[sl, sl])
        ranks.append(int(np.sum(ev > 1e-9 * ev.max())))
        Ps.append(Pj)
    ridge = 1e-9 * np.eye(m)
    null = m - sum(ranks)

    def fit(rho: NDArray):
        Pl = sum((10.0**r * P for r, P in zip(rho, Ps, strict=True)), np.zeros((m, m)))
        H = As + ridge + Pl
        try:
            L = np.linalg.cholesky(H)
        except np.linalg.LinAlgError:
            return None
        Hinv = np.linalg.inv(H)
        c = Hinv @ bs
        rss = max(rtr - 2.0 * c @ bs + c @ As @ c, 0.0)
        F_ = Hinv @ As
        edf = float(np.trace(F_))
        edf2 = 2.0 * edf - float(np.sum(F_ * F_.T))
        logdet = 2.0 * float(np.sum(np.log(np.diag(L))))
        return c, Hinv, rss, edf, rss + float(c @ Pl @ c), logdet, edf2

    def score(rho: NDArray) -> float:
        out = fit(rho)
        if out is None or out[3] >= R:
            return np.inf
        if criterion == "gcv":
            return math.log(R * max(out[2], 1e-300) / (R - out[3]) ** 2)
        ln10 = math.log(10.0)
        return (R - null) * math.log(max(out[4], 1e-300)) + out[5] - ln10 * float(np.dot(ranks, rho))

    grid = np.arange(LOG_LAMBDA[0], LOG_LAMBDA[1] + 1e-9, 0.5)
    k = len(Ps)
    common = min(grid, key=lambda g: score(np.full(k, g)))
    rho = np.full(k, common)
    if k:
        res = scipy.optimize.minimize(score, rho, method="L-BFGS-B", bounds=[LOG_LAMBDA] * k, options={"eps": 1e-4})
        if np.isfinite(res.fun) and score(res.x) <= score(rho):
            rho = res.x
    c, Hinv, rss, edf, _, _, edf2 = fit(rho)
    return _Solution(c / scale, Hinv / np.outer(scale, scale), 10.0**rho, edf, rss, edf2)


# ------------------------------------------------------------------------------------------ shapes


def _shape_columns(variable: str, x: NDArray) -> dict[str, list[tuple[NDArray, int, str]]]:
    """Each shape's candidate curves over x: (curve, sign constraint of the amplitude (0: free), detail)."""
    xm = max(float(np.max(np.abs(x))), 1e-300)
    if variable == "deflection":
        u = np.maximum(x / GAS_L, -0.9)
        gas = (1.0 - (1.0 + u) ** (-GAS_KAPPA)) - GAS_KAPPA * u
        band = [(np.sign(x) * np.maximum(np.abs(x) - f * xm, 0.0), 1, f"dead band +-{f * xm:.4g} m")
                for f in (0.2, 0.4, 0.6)]  # fmt: skip
        return {
            "linear_stiffness": [(x, 0, "")],
            "progressive_spring": [(x**3, 1, "")],
            "gas_spring": [(gas, 1, f"L = {GAS_L} m, kappa = {GAS_KAPPA}")],
            "dead_band": band,
        }
    return {
        "linear_damping": [(x, 0, "")],
        "coulomb_friction": [(np.tanh(x / COULOMB_EPS), 1, f"v_eps = {COULOMB_EPS} m/s")],
        "asymmetric_damping": [(x * np.tanh(x / ASYM_EPS), 0, f"v tanh(v / {ASYM_EPS}) (the library's)")],
        "one_sided_damping": [(np.maximum(x, 0.0), 1, "rebound only"), (np.minimum(x, 0.0), 1, "compression only")],
        "quadratic_damping": [(np.abs(x) * x, 0, "")],
        "sqrt_damper": [(np.sign(x) * np.sqrt(np.abs(x)), 1, "")],
    }


def resemblance(variable: str, x: NDArray, f: NDArray, se: NDArray, free_line: bool = False) -> Resemblance:
    """Best one-parameter match of the library's shapes to the curve f(x) [N] with standard errors se [N];
    `free_line`: f is known modulo a line through 0 (and given without its projection on x), and so is each
    shape (a linear stiffness or damping then matches nothing)."""
    floor = 1e-2 * max(float(np.median(se[se > 0])) if np.any(se > 0) else 1.0, 1e-300)
    w = 1.0 / np.maximum(se, floor) ** 2
    total = float(np.sum(w * f * f))
    r2, amp, detail = {}, {}, {}
    for name, options in _shape_columns(variable, x).items():
        best = (-np.inf, 0.0, "")
        for s, sign, text in options:
            if free_line:
                s = s - x * float(x @ s) / float(x @ x)
            ss = float(np.sum(w * s * s))
            a = float(np.sum(w * f * s)) / ss if ss > 0 else 0.0
            if sign and a * sign < 0:
                a = 0.0
            q = 1.0 - float(np.sum(w * (f - a * s) ** 2)) / total if total > 0 else 0.0
            if q > best[0]:
                best = (q, a, text)
        r2[name], amp[name] = float(best[0]), float(best[1])
        if best[2]:
            detail[name] = best[2]
    top = max(r2, key=lambda k: r2[k])
    return Resemblance(top, r2, amp, detail)


# ------------------------------------------------------------------------------------------ the estimate


def _trajectories(task, names: tuple[str, ...], X: NDArray):
    """Simulate the batch X (P, D): responses and each corner's deflection and velocity (P, n, 4)."""
    exp = task.experiment
    values = {n: X[:, j] for j, n in enumerate(names)}
    with np.errstate(all="ignore"):
        resp = exp.simulate(values)
        G = np.broadcast_to(exp.matrices(values).G, (X.shape[0], N_CORNERS, 3))
    Gt = np.swapaxes(G, -1, -2)[:, None, :, :]
    d = (resp.q[..., None, :3] @ Gt)[..., 0, :] - resp.q[..., 3:]
    v = (resp.qd[..., None, :3] @ Gt)[..., 0, :] - resp.qd[..., 3:]
    return resp, d, v


def estimate_unexplained(
    task,
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
    exp = task.experiment
    n, dt = exp.t.size, exp.dt
    families = tuple(reference)
    objective = task.objective(reference)
    sigma = {f: np.asarray(task.sigma[f], dtype=float) for f in families}
    use_nuisance = bool(nuisance and names)
    lo = np.array([task.lower[task.names.index(m)] if m in task.names else -np.inf for m in names])
    hi = np.array([task.upper[task.names.index(m)] if m in task.names else np.inf for m in names])

    def linearise(at: NDArray):
        """Residual, trajectories and the unknowns' sensitivities at `at` (one batched simulation)."""
        steps = np.zeros(0)
        if use_nuisance:
            width = np.where(np.isfinite(hi - lo), hi - lo, np.abs(at))
            h = 1e-6 * np.maximum(np.abs(at), np.maximum(1e-3 * width, 1e-9))
            steps = np.where(at + h <= hi, h, -h)
        X = np.vstack([at[None, :], at[None, :] + np.diag(steps)]) if steps.size else at[None, :]
        resp, d_all, v_all = _trajectories(task, names, X)
        res = np.asarray(objective.residuals(exp.read(resp)), dtype=float)  # (P, R_all)
        if not np.all(np.isfinite(res[0])):
            raise ValueError("the fitted model's residual is not finite")
        if steps.size:
            Jm = (-(res[1:] - res[0]) / steps[:, None]).T  # d model / dx / sigma
            dd = (d_all[1:] - d_all[0]) / steps[:, None, None]
            dv = (v_all[1:] - v_all[0]) / steps[:, None, None]
        else:
            Jm, dd, dv = np.zeros((res.shape[1], 0)), np.zeros((0, n, 4)), np.zeros((0, n, 4))
        car = _car_at(exp, {m: at[j] for j, m in enumerate(names)}, dt)
        return res[0], Jm, d_all[0], v_all[0], dd, dv, car

    r, Jm, d0, v0, dd, dv, car = linearise(x)
    R_all = r.size
    keep = np.ones(R_all, dtype=bool) if keep is None else np.asarray(keep, dtype=bool)
    if keep.shape != (R_all,):
        raise ValueError(f"keep must have {R_all} entries (family, time, channel), got {keep.shape}")
    R = int(keep.sum())
    p = Jm.shape[1]
    rk0 = r[keep]
    # the fit without the force: the unknowns' linearised re-fit at x (x itself when it is the fit's optimum)
    if p:
        Jk = Jm[keep]
        JtJ = Jk.T @ Jk + 1e-12 * np.trace(Jk.T @ Jk) * np.eye(p)
        c0 = np.linalg.solve(JtJ, Jk.T @ rk0)
        rss0 = min(float(np.sum((rk0 - Jk @ c0) ** 2)), float(rk0 @ rk0))
        edf0 = float(np.trace(np.linalg.solve(JtJ, Jk.T @ Jk)))
    else:
        rss0, edf0 = float(rk0 @ rk0), 0.0

    x_cur = x.copy()
    corr_d = np.zeros_like(d0)
    corr_v = np.zeros_like(v0)
    done = 0
    for it in range(max(0, iterations) + 1):
        d, v = d0 + corr_d, v0 + corr_v
        rk, Jk = r[keep], Jm[keep]
        # basis of each function on the current trajectory, inputs at the corners of its axle
        bases, cols = [], []
        for _axle, corners in AXLES:
            for traj in (d, v):
                b = _basis(traj[:, corners], n_knots)
                bases.append(b)
                U = np.zeros((n, N_CORNERS, b.size))
                for c in corners:
                    U[:, c, :] = b(traj[:, c])
                cols.append(U)
        U = np.concatenate(cols, axis=2)  # (n, 4, K)
        s = _responses(car, U)
        S = np.concatenate([_channel_columns(objective, f, car, s, U, sigma[f]) for f in families], axis=0)
        A = np.hstack([Jk, S[keep]])
        blocks, k0 = [], p
        for b in bases:
            blocks.append((slice(k0, k0 + b.size), b.P))
            k0 += b.size
        sol = _solve(A.T @ A, A.T @ rk, float(rk @ rk), R, blocks, criterion)
        theta, dx = sol.coef[p:], sol.coef[:p]
        # the trajectory of the corrected model: fitted + the unknowns' shift + the estimate's own response
        new_d = (s[:, :N_DOF, :] @ theta) @ car.D.T
        new_v = (s[:, N_DOF:, :] @ theta) @ car.D.T
        shift_d, shift_v = np.tensordot(dx, dd, axes=1), np.tensordot(dx, dv, axes=1)
        change = max(float(np.max(np.abs(new_d + shift_d - corr_d)) / np.ptp(d)),
                     float(np.max(np.abs(new_v + shift_v - corr_v)) / np.ptp(v)))  # fmt: skip
        if it == iterations or change < 1e-3:
            break
        done += 1
        corr_d, corr_v = new_d, new_v
        moved = float(np.max(np.abs(shift_d)) / np.ptp(d)) > 1e-4 or float(np.max(np.abs(shift_v)) / np.ptp(v)) > 1e-4
        if p and moved:  # a Gauss-Newton step of the unknowns: re-simulate there
            x_cur = np.clip(x_cur + dx, lo, hi)
            r, Jm, d0, v0, dd, dv, car = linearise(x_cur)
    dx_total = np.clip(x_cur + dx, lo, hi) - x

    # significance against the fit without the force
    rss1 = float(np.sum((rk - A @ sol.coef) ** 2))
    edf_force = max(sol.edf - edf0, 1e-9)
    df_test = max(sol.edf2 - edf0, edf_force)
    dof = max(R - sol.edf, 1.0)
    sigma2 = max(1.0, rss1 / dof)
    F = max(rss0 - rss1, 0.0) / df_test / sigma2
    p_value = float(stats.f.sf(F, df_test, dof))

    # curves, bands, resemblance
    V = sigma2 * sol.cov
    axles = []
    j, k0 = 0, p
    for axle, corners in AXLES:
        curves = []
        for var, traj in (("deflection", d), ("velocity", v)):
            b = bases[j]
            sl = slice(k0, k0 + b.size)
            grid = np.linspace(float(np.min(traj[:, corners])), float(np.max(traj[:, corners])), grid_points)
            Bg = b(grid)
            own = LINE_UNKNOWN[(axle, var)]
            if own in names[:p]:  # its line and the unknown's re-fit are one: the curve modulo lines
                rows = np.zeros((grid.size, sol.coef.size))
                rows[:, sl], rows[:, names.index(own)] = Bg, grid
                rows -= np.outer(grid, grid @ rows) / float(grid @ grid)
                f = rows @ sol.coef
                se = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", rows, V, rows), 0.0))
                line = A[:, names.index(own)]  # its response, and the part of the curve's the unknown absorbs
                contrib = A[:, sl] @ sol.coef[sl]
                contrib = contrib - line * float(line @ contrib) / max(float(line @ line), 1e-300)
            else:
                f = Bg @ sol.coef[sl]
                se = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", Bg, V[sl, sl], Bg), 0.0))
                contrib = A[:, sl] @ sol.coef[sl]
            i_peak = int(np.argmax(np.abs(f)))
            z = np.abs(f) / np.maximum(se, 1e-300)
            curves.append(
                Curve(
                    variable=var, grid=grid, force=f, band=np.vstack([f - Z95 * se, f + Z95 * se]),
                    peak_force=float(abs(f[i_peak])), peak_at=float(grid[i_peak]),
                    z_max=float(np.max(np.where(se > 0, z, 0.0))), chi2_explained=float(np.mean(contrib**2)),
                    lam=float(sol.lam[j]), resembles=resemblance(var, grid, f, se, free_line=own in names[:p]),
                )
            )  # fmt: skip
            j += 1
            k0 += b.size
        axles.append(AxleEstimate(axle, curves[0], curves[1]))
    return Unexplained(
        front=axles[0], rear=axles[1], chi2_before=float(np.mean(rk0**2)), chi2_after=rss1 / R,
        edf=float(edf_force), edf_total=float(sol.edf), df_test=float(df_test), F=float(F), p_value=p_value,
        sigma2=float(sigma2), samples=R, iterations=done, dx=dx_total, names=names,
    )  # fmt: skip


def candidate_order(unexplained: Unexplained, effect_names: Sequence[str], alpha: float = ALPHA) -> list[str]:
    """`effect_names` (library effects and ``parameter:kf``-style candidates) ordered best first by how well the
    significant estimated curves resemble each one's shape (R² x affinity of the shape to the effect, weighted by
    the residual power each curve explains); names the estimate does not point to keep their order after the
    others. Unchanged when the estimate is not significant (p >= alpha)."""
    names = list(effect_names)
    if not unexplained.p_value < alpha:
        return names
    score = {name: 0.0 for name in names}
    total = sum(c.chi2_explained for a in (unexplained.front, unexplained.rear) for c in (a.g, a.h)) or 1.0
    for a in (unexplained.front, unexplained.rear):
        tag = a.axle[0]
        for c in (a.g, a.h):
            if not c.significant:
                continue
            weight = c.chi2_explained / total
            for shape, r2 in c.resembles.r2.items():
                for effect, affinity in SHAPE_EFFECTS[shape]:
                    effect = effect.format(axle=tag)
                    if effect in score:
                        score[effect] = max(score[effect], weight * max(r2, 0.0) * affinity)
    return sorted(names, key=lambda e: (-score[e], names.index(e)))
