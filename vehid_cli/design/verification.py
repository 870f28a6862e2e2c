"""`--verify N`: campaigns of N identifications on the configured and on the designed test, so that the bound the
design optimised is checked against what identify achieves (per-run NRE RMS over the bound on both tests)."""

from __future__ import annotations

from dataclasses import dataclass

from ..campaign.executor import Executor
from ..campaign.runner import run_campaign
from ..config import Config, config_from_dict
from .scoring import Progress


@dataclass(frozen=True)
class Verification:
    """Campaigns on both tests: the achieved per-run NRE RMS beside the bound."""

    runs: int
    configured_nre_rms: float
    configured_bound: float
    designed_nre_rms: float
    designed_bound: float

    @property
    def configured_ratio(self) -> float:
        return self.configured_nre_rms / self.configured_bound

    @property
    def designed_ratio(self) -> float:
        return self.designed_nre_rms / self.designed_bound

    @property
    def achieved_factor(self) -> float:
        """The achieved NRE's improvement (configured over designed)."""
        return self.configured_nre_rms / self.designed_nre_rms


def verification_campaigns(config: Config, configured: Config, designed: Config, runs: int, executor: Executor,
                           progress: Progress) -> Verification:  # fmt: skip
    """An N-run campaign on each test (the config's identify settings): per-run NRE RMS and the bound."""
    out = []
    for label, cfg in (("configured", configured), ("designed", designed)):
        raw = cfg.model_dump(mode="json", exclude_none=True, by_alias=True)
        raw["identify"]["runs"] = runs
        campaign = run_campaign(
            config_from_dict(raw, source=config.source), executor=executor,
            on_run=lambda done, total, label=label: progress(f"verify {label}", done, total),
        )  # fmt: skip
        out.append((campaign.summary.per_run_nre_rms, campaign.bound.nre_rms_percent))
    (cn, cb), (dn, db) = out
    return Verification(runs, float(cn), float(cb), float(dn), float(db))
