"""Can the data tell effects apart at all? Checks made before any effect is claimed (issue 6, item 5).

A diagnosis on data that is too short, too noisy or not excited enough must say so rather than name an
effect. Three checks, each with its threshold stated here:

* length: at least MIN_SAMPLES samples per channel (and, on a bench, MIN_REVERSALS velocity reversals:
  two full strokes), else the residual statistics have too few degrees of freedom to mean anything;
* noise: the noise the data implies (its sigma, given or estimated) at most MAX_NOISE_RATIO of the
  signal's standard deviation, else the residual is mostly noise and a missing effect is buried in it;
* excitation: on the car, the road moves the wheels at all, and differently left and right (the
  left-minus-right road of an axle at least MIN_ROLL_RATIO of left-plus-right): equal bumps left and right
  leave roll unexcited, and a missing strut effect then hides in the declared parameters;
  on a bench, MIN_REVERSALS strokes; and the Fisher information of the declared unknowns is not singular
  (every 95 % interval finite), else the data cannot even pin down the declared model and an effect's parameters would
  trade off against its parameters;
* telling effects apart (in the loop, attribution.distinct): the best candidate must beat every other
  significant one by the critical value of its own test, else the data prefers neither and none is added.

When any check fails the loop still ranks the candidates (for the record) but accepts none.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ..core.result import Result
from ..models.noise import per_channel

MIN_SAMPLES = 500
MIN_REVERSALS = 4
MAX_NOISE_RATIO = 0.5
MIN_ROLL_RATIO = 0.01


@dataclass(frozen=True)
class Quality(Result):
    """Why the data cannot support a claim (empty: it can)."""

    reasons: tuple[str, ...] = ()
    samples: int = 0
    noise_ratio: float | None = None  # median over channels of sigma / std(signal)
    worst_relative_ci: float | None = None  # largest 95 % half-width / |estimate| among declared unknowns
    before_fit: bool = False  # a check that needs no fit failed (length, noise, excitation): nothing was fitted

    @property
    def ok(self) -> bool:
        return not self.reasons

    def to_json(self) -> dict:
        return {
            "ok": self.ok,
            "reasons": list(self.reasons),
            "samples": self.samples,
            "noise_ratio": self.noise_ratio,
            "worst_relative_ci95": self.worst_relative_ci,
        }


def _checks(samples: int, noise_ratio: float, names, x: NDArray, ci: NDArray, extra: list[str]) -> Quality:
    reasons = list(extra)
    if samples < MIN_SAMPLES:
        reasons.insert(0, f"too short: {samples} samples per channel, at least {MIN_SAMPLES} needed")
    if not noise_ratio <= MAX_NOISE_RATIO:
        reasons.append(
            f"too noisy: the noise is {100 * noise_ratio:.0f} % of the signal (at most {100 * MAX_NOISE_RATIO:.0f} %)"
        )
    x, ci = np.asarray(x, dtype=float), np.asarray(ci, dtype=float)
    rel = np.where(np.abs(x) > 0, ci / np.maximum(np.abs(x), 1e-300), np.inf)
    rel = np.where(np.isfinite(rel), rel, np.inf)
    loose = [n for n, r in zip(names, rel, strict=True) if not np.isfinite(r)]
    if loose:
        reasons.append(
            f"not excited enough to determine the declared model: {', '.join(loose)} undetermined "
            "(singular Fisher information)"
        )
    worst = float(np.max(rel)) if rel.size and np.all(np.isfinite(rel)) else None
    return Quality(tuple(reasons), int(samples), float(noise_ratio), worst)


def _std(values: NDArray) -> NDArray:
    """Standard deviation over time (k,) of values (n, k)."""
    return np.std(values, axis=0)


def precheck_vehicle(task, reference) -> Quality:
    """The car's checks that need no fit: samples of the run, sigma over each channel's std (over its own samples),
    roll excitation. Several runs (a JointTask and its tuple of references): the samples of all runs, the median
    ratio over every run's channels, roll excited on at least one run's road."""
    tasks = getattr(task, "tasks", (task,))
    refs = reference if isinstance(reference, tuple) else (reference,)
    ratios = np.concatenate(
        [
            np.asarray(t.sigma[f], dtype=float)
            / np.maximum(per_channel(_std, ref, None if t.observed is None else t.observed[f]), 1e-300)
            for t, r in zip(tasks, refs, strict=True)
            for f, ref in r.items()
        ]
    )
    roll, moving = 0.0, False
    for t in tasks:
        y = np.asarray(t.experiment.road, dtype=float)  # corners 1, 2 front; 4, 3 rear; 1 and 4 on side b1
        pairs = ((0, 1), (3, 2))
        moving = moving or bool(np.any(y))
        roll = max(roll, *(np.linalg.norm(y[:, a] - y[:, b]) / max(np.linalg.norm(y[:, a] + y[:, b]), 1e-300)
                           for a, b in pairs))  # fmt: skip
    extra = []
    if not moving:
        extra.append("not excited: the road input is zero")
    elif roll < MIN_ROLL_RATIO:
        extra.append(
            f"not excited enough: the road is the same left and right (difference {100 * roll:.2g} % of the sum), "
            "so roll is not excited"
        )
    samples = sum(int(t.experiment.t.size) for t in tasks)
    q = _checks(samples, float(np.median(ratios)), (), np.zeros(0), np.zeros(0), extra)
    return replace(q, before_fit=not q.ok)


def assess_vehicle(task, reference: dict[str, NDArray], before, pre: Quality | None = None) -> Quality:
    """Every check for the full car: the pre-fit ones (`pre`, else computed) and the declared fit's CIs."""
    pre = pre if pre is not None else precheck_vehicle(task, reference)
    n = len(task.names)
    post = _checks(pre.samples, pre.noise_ratio, task.names, before.x[:n], before.ci[:n], [])
    reasons = tuple(dict.fromkeys(pre.reasons + post.reasons))
    return Quality(reasons, pre.samples, pre.noise_ratio, post.worst_relative_ci, pre.before_fit)


def assess_bench(history, sigma: float, names, before) -> Quality:
    """The checks for a damper on a bench: samples and strokes, force noise over force std, the declared CIs."""
    v = np.asarray(history.v, dtype=float)
    moving = v[np.abs(v) > 1e-3 * max(np.max(np.abs(v)), 1e-300)]
    reversals = int(np.count_nonzero(np.diff(np.sign(moving)) != 0))
    extra = []
    if reversals < MIN_REVERSALS:
        extra.append(f"too few strokes: {reversals} velocity reversals, at least {MIN_REVERSALS} needed")
    ratio = float(sigma / max(float(np.std(history.force)), 1e-300))
    n = len(names)
    return _checks(int(history.t.size), ratio, names, before.x[:n], before.ci[:n], extra)
