"""What `vehid design` returns (`DesignResult`): the configured and the designed test with their bounds, what the
search learned (profiles, proposals, cost), and the improvement factors, computed once here so that every table,
JSON document and figure of `report/design.py` shows the same numbers."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .criterion import Evaluation
from .profiles import Profile
from .proposals import Proposal
from .space import Space
from .verification import Verification


@dataclass(frozen=True)
class DesignResult:
    """The configured test, the designed one, and what the search learned; ratios computed once here."""

    criterion: str
    configured: Evaluation
    designed: Evaluation
    space: Space
    unidentifiable: tuple[str, ...]  # unknowns the configured test cannot identify
    proposals: tuple[Proposal, ...]  # cheapest first
    sweeps: tuple[Profile, ...]  # the figures' profiles (named as the JSON document's key `sweeps`)
    evaluations: int
    wall_s: float  # the design (search, profiles, proposals), without --verify's campaigns [s]
    jobs: int
    noise_note: str
    verification: Verification | None = None
    improvement: float = dataclasses.field(init=False)  # the criterion's factor (configured over designed)
    nre_improvement: float = dataclasses.field(init=False)
    parameter_improvement: NDArray = dataclasses.field(init=False)

    def __post_init__(self) -> None:
        c, d = self.configured, self.designed
        if self.criterion.startswith("d_optimal"):  # the factor on the geometric mean of the bounds' sd
            D = len(d.bound.names)
            factor = math.exp((d.log_det - c.log_det) / (2 * D)) if math.isfinite(c.log_det) else math.inf
        else:
            factor = _ratio(c.criterion, d.criterion)
        object.__setattr__(self, "improvement", factor)
        object.__setattr__(self, "nre_improvement", _ratio(c.bound.nre_rms_percent, d.bound.nre_rms_percent))
        with np.errstate(divide="ignore", invalid="ignore"):
            per = np.asarray(c.bound.re_sd_percent) / np.asarray(d.bound.re_sd_percent)
        object.__setattr__(self, "parameter_improvement", per)


def _ratio(a: float, b: float) -> float:
    if b == 0 or not math.isfinite(b):
        return math.nan
    return a / b if math.isfinite(a) else math.inf
