"""The force a damper model misses on a test bench, non-parametrically.

On a bench the motion is prescribed, so the force the final model leaves unexplained is a function of the measured
displacement x [m], velocity v [m/s] (and control u, where it varies) sample by sample, with no dynamics between:

    r(t) = F_measured - F_model = c + g(x) + h(v) [+ k(u)]

* g, h (and k) are the cubic P-splines of psplines.py (vanishing at 0, their lines through 0 free), c a constant
  (a force offset); one smoothing parameter per function by REML, fitted to the training samples the model was
  fitted on: h (and k) first, then g on what they leave, kept only when the data demand it (``chosen_law``); the
  bands of g are conditional on h.
* The residual of model error on a bench is smooth, not white: the bands use the residual's own variance inflated by
  (1 + rho) / (1 - rho) (rho its lag-1 autocorrelation, as the loop's tests count n (1 - rho) / (1 + rho) effective
  samples), and so does the F test of the law against the constant alone.
* Held out: Eq. 7's J of the model plus the law on every held-out run (or the held-out blocks), beside the model's
  own: the law is worth showing when it lowers the held-out J (on every held-out run); outside the training range a
  curve is held at its end value (no extrapolation).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..core.result import Result
from .psplines import Basis, PenalisedFit, basis, penalised_fit
from .residuals import autocorrelation
from .tails import f_sf

Z95 = 1.959963984540054
SIGNIFICANCE = 1e-3
SIGNIFICANT_Z = 3.0
UNITS = {"displacement": "m", "velocity": "m/s", "control": "-"}


@dataclass(frozen=True)
class LawCurve(Result):
    """One function of the missing force over one variable, with its 95 % band."""

    variable: str  # displacement, velocity or control
    grid: NDArray
    force: NDArray  # [N]
    band: NDArray  # (2, G) [N]
    peak_force: float
    peak_at: float
    z_max: float
    lam: float

    @property
    def significant(self) -> bool:
        return bool(self.z_max > SIGNIFICANT_Z)

    def to_json(self) -> dict:
        return {
            "variable": self.variable, "unit": UNITS[self.variable], "grid": self.grid.tolist(),
            "force_N": self.force.tolist(), "band95_N": [self.band[0].tolist(), self.band[1].tolist()],
            "peak_force_N": self.peak_force, "peak_at": self.peak_at, "z_max": self.z_max,
            "significant": self.significant, "lambda": self.lam,
        }  # fmt: skip


@dataclass(frozen=True)
class BenchLaw(Result):
    """The non-parametric law of the force the final damper model misses, and what it does to the held-out J."""

    curves: tuple[LawCurve, ...]
    offset: float  # c [N]
    J_before: float  # Eq. 7 on the training samples: the model
    J_after: float  # the model plus the law
    validation_J_parametric: float  # held-out J of the model (mean over held-out runs)
    validation_J_non_parametric: float  # held-out J of the model plus the law
    validation_per_file: dict[str, tuple[float, float]] | None  # run -> (parametric, with the law)
    edf: float
    F: float
    p_value: float
    rho: float  # lag-1 autocorrelation of the training residual
    samples: int
    noun: str = "damper force"

    @property
    def lowers_validation(self) -> bool:
        """Does the law lower the held-out J (on every held-out run)?"""
        per = self.validation_per_file or {}
        every = all(b < a for a, b in per.values())
        return bool(self.validation_J_non_parametric < self.validation_J_parametric and every)

    @property
    def significant(self) -> bool:
        return bool(self.p_value < SIGNIFICANCE and any(c.significant for c in self.curves))

    @property
    def dominant(self) -> LawCurve:
        return max(self.curves, key=lambda c: c.peak_force)

    def summary(self) -> str:
        c = self.dominant
        unit = UNITS[c.variable]
        at = f"{1e3 * c.peak_at:.3g} mm" if c.variable == "displacement" else f"{c.peak_at:.3g} {unit}"
        held = f"held-out J {self.validation_J_parametric:.4g} -> {self.validation_J_non_parametric:.4g} with it"
        if not self.lowers_validation:
            held += " (it does not carry over to every held-out run: a law of this run's motion only)"
        return f"peaks at {c.peak_force:.3g} N over {c.variable} (at {at}); {held}"

    def to_json(self) -> dict:
        return {
            "kind": "bench",
            "law": "F_measured - F_model = c + " + " + ".join(f"f({c.variable})" for c in self.curves),
            "curves": {c.variable: c.to_json() for c in self.curves},
            "offset_N": self.offset,
            "J_before": self.J_before,
            "J_after": self.J_after,
            "validation_J_parametric": self.validation_J_parametric,
            "validation_J_non_parametric": self.validation_J_non_parametric,
            "validation_J_per_file": None if self.validation_per_file is None else
            {k: {"parametric": a, "non_parametric": b} for k, (a, b) in self.validation_per_file.items()},
            "lowers_validation": self.lowers_validation,
            "edf": self.edf, "F": self.F, "p_value": self.p_value, "significant": self.significant,
            "residual_lag1_autocorrelation": self.rho, "samples": self.samples,
            "peak_force_N": self.dominant.peak_force, "acts_on": self.dominant.variable,
        }  # fmt: skip


@dataclass(frozen=True)
class LawFit:
    """The fitted law: its bases (one per variable), the penalised solution (constant first) and the variance scale."""

    variables: tuple[str, ...]
    bases: tuple[Basis, ...]
    sol: PenalisedFit
    sigma2: float
    ranges: tuple[tuple[float, float], ...]

    def design(self, values: Mapping[str, NDArray]) -> NDArray:
        """(n, 1 + K) columns: the constant, then each variable's basis (held at the training range's ends)."""
        cols = [np.ones((np.asarray(values[self.variables[0]]).size, 1))]
        for name, b, (lo, hi) in zip(self.variables, self.bases, self.ranges, strict=True):
            cols.append(b(np.clip(np.asarray(values[name], dtype=float), lo, hi)))
        return np.hstack(cols)

    def __call__(self, values: Mapping[str, NDArray]) -> NDArray:
        """The missing force [N] at the samples `values` (variable -> (n,))."""
        return self.design(values) @ self.sol.coef


def fit_law(values: Mapping[str, NDArray], residual: NDArray, n_knots: int = 10) -> LawFit:
    """Fit c + sum_j f_j(values[j]) to `residual` [N] (the variables whose values vary), REML per function."""
    r = np.asarray(residual, dtype=float)
    names = tuple(n for n, v in values.items() if np.ptp(np.asarray(v, dtype=float)) > 0)
    bases = tuple(basis(np.asarray(values[n], dtype=float), n_knots) for n in names)
    ranges = tuple((float(np.min(values[n])), float(np.max(values[n]))) for n in names)
    blocks, k0 = [], 1
    for b in bases:
        blocks.append((slice(k0, k0 + b.size), b.P))
        k0 += b.size
    probe = LawFit(names, bases, PenalisedFit(np.zeros(k0), np.eye(k0), np.ones(len(names)), 0.0, 0.0, 0.0), 1.0,
                   ranges)  # fmt: skip
    A = probe.design(values)
    sol = penalised_fit(A.T @ A, A.T @ r, float(r @ r), r.size, blocks)
    rss = float(np.sum((r - A @ sol.coef) ** 2))
    e = r - A @ sol.coef
    rho = float(np.clip(autocorrelation(e, 1)[1], 0.0, 0.99))
    sigma2 = rss / max(r.size - sol.edf, 1.0) * (1.0 + rho) / (1.0 - rho)
    return LawFit(names, bases, sol, sigma2, ranges)


@dataclass(frozen=True)
class StagedLaw:
    """The law fitted in stages (velocity and control first, then displacement on what they leave): the sum of
    each stage's LawFit."""

    stages: tuple[LawFit, ...]

    def __call__(self, values: Mapping[str, NDArray]) -> NDArray:
        return sum((f(values) for f in self.stages), np.zeros(np.asarray(next(iter(values.values()))).size))

    @property
    def edf(self) -> float:
        return float(sum(f.sol.edf for f in self.stages))


def _significant(fit: LawFit, values: Mapping[str, NDArray], r: NDArray) -> bool:
    """The F test of `fit` against a constant on r, over the effective samples n (1 - rho) / (1 + rho)."""
    e = r - fit(values)
    rss1, rc = float(e @ e), r - np.mean(r)
    rho = float(np.clip(autocorrelation(e, 1)[1], 0.0, 0.99))
    n_eff = r.size * (1.0 - rho) / (1.0 + rho)
    df = max(fit.sol.edf - 1.0, 1e-9)
    F = max(float(rc @ rc) - rss1, 0.0) / df / max(rss1 / max(r.size - fit.sol.edf, 1.0), 1e-300) * n_eff / r.size
    return float(f_sf(F, df, max(n_eff - fit.sol.edf, 1.0))) < SIGNIFICANCE


def chosen_law(values: Mapping[str, NDArray], r: NDArray, n_knots: int) -> StagedLaw:
    """The law over velocity (and control, where it varies) first, then over displacement on what it leaves, kept
    only when the training data demand it (the F test at SIGNIFICANCE over the effective samples). Not one joint
    fit: on a sine x² / A² + v² / (A w)² = 1, so the even parts of g(x) and h(v) trade off against each other at
    one amplitude and frequency, and a joint split does not carry over to another run (on the MR damper the joint
    law raised the held-out J threefold where the staged one lowers it on every held-out run)."""
    first = {k: v for k, v in values.items() if k != "displacement" and np.ptp(np.asarray(v, dtype=float)) > 0}
    stages = []
    rest = np.asarray(r, dtype=float)
    if first:
        stages.append(fit_law(first, rest, n_knots))
        rest = rest - stages[0](values)
    if "displacement" in values and np.ptp(np.asarray(values["displacement"], dtype=float)) > 0:
        g = fit_law({"displacement": values["displacement"]}, rest, n_knots)
        if not stages or _significant(g, values, rest):
            stages.append(g)
    return StagedLaw(tuple(stages))


def _curve(fit: LawFit, j: int, grid_points: int) -> LawCurve:
    lo, hi = fit.ranges[j]
    grid = np.linspace(lo, hi, grid_points)
    k0 = 1 + sum(b.size for b in fit.bases[:j])
    sl = slice(k0, k0 + fit.bases[j].size)
    B = fit.bases[j](grid)
    f = B @ fit.sol.coef[sl]
    V = fit.sigma2 * fit.sol.cov[sl, sl]
    se = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", B, V, B), 0.0))
    i = int(np.argmax(np.abs(f)))
    z = np.where(se > 0, np.abs(f) / np.maximum(se, 1e-300), 0.0)
    return LawCurve(fit.variables[j], grid, f, np.vstack([f - Z95 * se, f + Z95 * se]), float(abs(f[i])),
                    float(grid[i]), float(np.max(z)), float(fit.sol.lam[j]))  # fmt: skip


def eq7(measured: NDArray, model: NDArray) -> float:
    """Fleps-Dezasse Eq. 7: mean squared force error over the variance of the measured force."""
    return float(np.mean((measured - model) ** 2) / np.var(measured))


def bench_law(
    train: Mapping[str, NDArray],
    held_out: Mapping[str, Mapping[str, NDArray]],
    *,
    grid_points: int = 41,
    n_knots: int = 10,
) -> BenchLaw:
    """The law of the force the model misses: `train` holds the training samples' `force` (measured), `model` (the
    final model's force) and the variables (`displacement`, `velocity`, optionally `control`); `held_out` the same
    per held-out run (name -> arrays). See the module doc."""
    variables = {k: np.asarray(train[k], dtype=float) for k in UNITS if k in train}
    measured, model = np.asarray(train["force"], dtype=float), np.asarray(train["model"], dtype=float)
    r = measured - model
    law = chosen_law(variables, r, n_knots)
    rc = r - np.mean(r)
    rss1 = float(np.sum((r - law(variables)) ** 2))
    rss0 = float(rc @ rc)
    edf = law.edf
    df = max(edf - 1.0, 1e-9)
    e = r - law(variables)
    rho = float(np.clip(autocorrelation(e, 1)[1], 0.0, 0.99))
    n_eff = r.size * (1.0 - rho) / (1.0 + rho)
    F = max(rss0 - rss1, 0.0) / df / max(rss1 / max(r.size - edf, 1.0), 1e-300) * n_eff / r.size
    p = float(f_sf(F, df, max(n_eff - edf, 1.0)))
    per = {}
    for name, h in held_out.items():
        hv = {k: np.asarray(h[k], dtype=float) for k in variables}
        hm, hf = np.asarray(h["model"], dtype=float), np.asarray(h["force"], dtype=float)
        per[name] = (eq7(hf, hm), eq7(hf, hm + law(hv)))
    vp = float(np.mean([a for a, _ in per.values()])) if per else float("nan")
    vn = float(np.mean([b for _, b in per.values()])) if per else float("nan")
    return BenchLaw(
        curves=tuple(_curve(f, j, grid_points) for f in law.stages for j in range(len(f.variables))),
        offset=float(sum(f.sol.coef[0] for f in law.stages)), J_before=eq7(measured, model),
        J_after=eq7(measured, model + law(variables)), validation_J_parametric=vp, validation_J_non_parametric=vn,
        validation_per_file=per if len(per) > 1 else None, edf=edf, F=float(F), p_value=p, rho=rho,
        samples=int(r.size),
    )  # fmt: skip
