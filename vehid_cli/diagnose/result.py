"""What a diagnosis reports: each model's fit (`ModelReport`), each accepted step (`Step`) and the whole outcome
(`Diagnosis`: the verdict, before and after, candidates, checks, units, model uncertainty), with their JSON; and
the noise limit of the residual power (`chi2_limit`) the verdict is judged against."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from ..core.result import Result
from .attribution import Ranked
from .bench_law import BenchLaw
from .quality import Quality
from .residuals import ResidualAnalysis
from .uncertainty import ModelUncertainty
from .unexplained import Unexplained


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
    units: dict[str, str] = field(default_factory=dict)  # SI unit of each estimate before and after ('' unknown)
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
        if self.selected:  # a rival pair the data could not tell apart is said: one of them may still be missing
            then = f" (then stopped: {ambiguous})" if ambiguous else ""
            return f"found: {found}; the residual is now at the noise{level}{then}"
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
            "units": dict(self.units),
            "model_uncertainty": None if self.model_uncertainty is None else self.model_uncertainty.to_json(),
        } | ({"data_files": list(self.data_files)} if self.data_files else {})
