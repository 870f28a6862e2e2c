"""What a campaign produced: one record per run, the summary statistics (computed once) and the whole campaign.

Plain data shared by every system (the car, the damper on a bench): `systems` make RunRecords, `campaign`
collects them, `results` writes and reads them, `report` renders them.
"""

from __future__ import annotations

import hashlib
import io
import warnings
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..config import AnyConfig
from ..core.files import atomic_path, read_regular
from ..core.jsonio import finite_or_none
from ..core.result import Result
from ..optimizers.base import Problem
from .crlb import CramerRao

Z95 = 1.959963984540054  # the two-sided 95 % point of the standard normal distribution
BOUND_TOL = 1e-6  # an estimate within this fraction of its box's width of a bound sits on it
PENALTY = Problem.__dataclass_fields__["penalty"].default  # the cost of a NaN/Inf evaluation (optimizers/base.py)


def worst_first(chi2: dict[str, float]) -> list[str]:
    """Channel names by their chi² per sample, largest (the worst fitted) first; NaN (no samples) last, ties in the
    given order."""
    known = [n for n, v in chi2.items() if not np.isnan(v)]
    return sorted(known, key=lambda n: -chi2[n]) + [n for n in chi2 if n not in known]


def _digest(arrays: dict[str, np.ndarray]) -> str:
    """SHA-256 of named arrays (names, dtypes, shapes and bytes, in name order)."""
    h = hashlib.sha256()
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(f"{name} {a.dtype.str} {a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


@dataclass(frozen=True)
class RunRecord:
    """The outcome of one identification run."""

    index: int
    estimate: NDArray  # (D,)
    cost: float
    evaluations: int
    penalised: int
    wall_s: float
    history_evals: NDArray  # cumulative evaluations at each record of the best cost
    history_cost: NDArray  # best cost so far
    truth_cost: float = float("nan")  # cost of the true parameters on this run's data (NaN: truth unknown)
    chi2: float = float("nan")  # noise-weighted residual power per sample at the estimate (~1 for an adequate model)
    initial_cost: float = float("nan")  # cost at the start point (a damper fit's J before; NaN: not recorded)
    channel_chi2: NDArray = field(default_factory=lambda: np.zeros(0))  # chi² per sample of each measured channel

    @property
    def at_penalty(self) -> bool:
        """The run found no parameter set the model simulates usefully: its best cost is the penalty (or worse),
        so its estimate is meaningless."""
        return bool(self.cost >= PENALTY)

    @property
    def converged(self) -> bool | None:
        """Found the global minimum's basin: a cost no higher than the truth's on the same data (None: unknown)."""
        if not np.isfinite(self.truth_cost):
            return None
        return bool(self.cost <= self.truth_cost * (1 + 1e-9))

    def save(self, path: Path) -> None:
        """A checkpoint record: every field, and the SHA-256 of them all (a damaged record is never trusted)."""
        arrays = {k: np.asarray(v) for k, v in self.__dict__.items()}
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            np.savez(fh, sha256=np.array(_digest(arrays)), **arrays)

    @classmethod
    def load(cls, path: Path, limit: int = 64 << 20) -> RunRecord:
        """A record `save` wrote; ValueError when its fields do not match the digest it was written with, or are
        not what `save` writes (a number where a number belongs, 1-D arrays, a finite estimate); InputError when
        the file is not a regular file of at most `limit` bytes."""
        data = read_regular(path, limit, "checkpoint record")
        with zipfile.ZipFile(io.BytesIO(data)) as archive:
            packed = [i.filename for i in archive.infolist() if i.compress_type != zipfile.ZIP_STORED]
            if packed:
                raise ValueError(f"compressed members {packed[:3]}, which np.savez never writes")
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            fields = {k: z[k] for k in z.files if k != "sha256"}
            if "sha256" in z and str(z["sha256"]) != _digest(fields):
                raise ValueError("its fields do not match the SHA-256 it was written with")
        number, count = _field(fields, "f"), _field(fields, "i")
        record = cls(
            index=count("index"), estimate=_field(fields, "f", 1)("estimate"), cost=number("cost"),
            evaluations=count("evaluations"), penalised=count("penalised"), wall_s=number("wall_s"),
            history_evals=_field(fields, "i", 1)("history_evals"), history_cost=_field(fields, "f", 1)("history_cost"),
            truth_cost=number("truth_cost"), chi2=number("chi2"),
            initial_cost=number("initial_cost") if "initial_cost" in fields else float("nan"),
            channel_chi2=_field(fields, "f", 1)("channel_chi2") if "channel_chi2" in fields else np.zeros(0),
        )  # fmt: skip
        if not np.isfinite(record.estimate).all():
            raise ValueError("its estimate is not finite")
        if record.history_evals.shape != record.history_cost.shape:
            raise ValueError("its history of evaluations and of costs differ in length")
        return record


def _field(fields: dict[str, np.ndarray], kinds: str, ndim: int = 0):
    """A reader of one field of a record: a number (ndim 0, int for kinds 'i') or a 1-D array; ValueError naming
    the field when it is missing or of another type or shape."""

    def read(name: str):
        if name not in fields:
            raise ValueError(f"no field '{name}'")
        a = fields[name]
        ok = "iub" if kinds == "i" else "fiub"
        if kinds == "i" and ndim and a.dtype.kind == "f" and (a.size == 0 or bool(np.all(a == np.round(a)))):
            ok = "f"  # counts held as whole floats (an empty history is float64)
        if a.ndim != ndim or a.dtype.kind not in ok:
            raise ValueError(f"field '{name}' has type {a.dtype} and shape {a.shape}")
        if ndim:
            return a.astype(np.int64 if kinds == "i" else float)
        value = a[()]
        if kinds == "i":
            if int(value) < 0:
                raise ValueError(f"field '{name}' is negative")
            return int(value)
        return float(value)

    return read


@dataclass(frozen=True)
class Summary:
    """Figures of merit of a campaign (SPEC section 4), computed once."""

    names: tuple[str, ...]
    truth: NDArray | None
    mean: NDArray  # mean estimate over runs (D,)
    sd: NDArray  # standard deviation of the estimates over runs (D,)
    re_percent: NDArray | None  # RE of the mean (D,)
    nre_percent: float | None  # NRE of the mean (the paper's figure)
    per_run_re_percent: NDArray | None  # (N, D)
    per_run_nre_percent: NDArray | None  # (N,)
    crlb_re_sd_percent: NDArray  # (D,)
    crlb_nre_rms_percent: float
    evaluations: NDArray  # (N,)
    penalised: int
    wall_s: float
    converged: int | None = None  # runs whose cost is no higher than the truth's (None: truth unknown)
    at_penalty: int = 0  # runs that found no usable parameter set (best cost = the penalty): meaningless estimates
    chi2_median: float = float("nan")  # median over runs of the residual power over the noise power
    residual_samples: int = 0  # R, the number of weighted residuals behind chi2

    @property
    def chi2_limit(self) -> float:
        """Largest chi² per sample an adequate model gives: 1 + 5 sd of a chi² mean over R samples."""
        return 1.0 + 5.0 * np.sqrt(2.0 / max(self.residual_samples, 1))

    @property
    def model_inadequate(self) -> bool:
        """The residual is far above the noise the data implies: the model lacks something (or the noise level
        set by noise.level is too small)."""
        return bool(np.isfinite(self.chi2_median) and self.chi2_median > self.chi2_limit)

    @property
    def per_run_nre_median(self) -> float | None:
        return None if self.per_run_nre_percent is None else float(np.median(self.per_run_nre_percent))

    @property
    def per_run_nre_rms(self) -> float | None:
        return None if self.per_run_nre_percent is None else float(np.sqrt(np.mean(self.per_run_nre_percent**2)))

    @property
    def nre_over_crlb(self) -> float | None:
        """Per-run NRE RMS over the bound's NRE RMS: 1.0 is the physical limit."""
        rms = self.per_run_nre_rms
        if rms is None or not np.isfinite(self.crlb_nre_rms_percent) or self.crlb_nre_rms_percent <= 0:
            return None
        return rms / self.crlb_nre_rms_percent

    @property
    def re_sd_percent(self) -> NDArray:
        """Spread of the estimates over runs, relative to the truth (or to the mean when unknown) [%]."""
        ref = self.truth if self.truth is not None else self.mean
        with np.errstate(divide="ignore", invalid="ignore"):  # a mean of zero: no relative spread (inf), quietly
            return 100.0 * self.sd / np.abs(ref)


def summarise(
    names, truth, records: list[RunRecord], bound: CramerRao, wall_s: float, residual_samples: int = 0
) -> Summary:
    """Statistics of a list of runs against the truth (when known) and the Cramér–Rao bound."""
    est = np.array([r.estimate for r in records])
    mean, sd = est.mean(axis=0), est.std(axis=0, ddof=1) if len(records) > 1 else np.zeros(est.shape[1])
    re = nre = per_re = per_nre = None
    if truth is not None:
        with np.errstate(divide="ignore", invalid="ignore"):  # a true value of 0 has no relative error: inf/nan
            re = 100.0 * (mean - truth) / truth
            nre = float(np.linalg.norm(re))
            per_re = 100.0 * (est - truth) / truth
            per_nre = np.linalg.norm(per_re, axis=1)
    return Summary(
        names=tuple(names),
        truth=truth,
        mean=mean,
        sd=sd,
        re_percent=re,
        nre_percent=nre,
        per_run_re_percent=per_re,
        per_run_nre_percent=per_nre,
        crlb_re_sd_percent=bound.re_sd_percent,
        crlb_nre_rms_percent=bound.nre_rms_percent,
        evaluations=np.array([r.evaluations for r in records]),
        penalised=int(sum(r.penalised for r in records)),
        wall_s=wall_s,
        converged=None if truth is None else int(sum(bool(r.converged) for r in records)),
        at_penalty=int(sum(r.at_penalty for r in records)),
        chi2_median=float(np.median([r.chi2 for r in records])),
        residual_samples=residual_samples,
    )


@dataclass(frozen=True)
class Campaign(Result):
    """A finished campaign of any system: the task's description, every run, the bound and the summary, plus what
    the system concluded after the runs (`findings`: the damper's identified model, held-out J, real-time check
    and force traces; None for the car). Its JSON is SPEC section 5's, its file layout `campaign/results.py`'s."""

    config: AnyConfig
    data_file: str | None
    names: tuple[str, ...]
    truth: NDArray | None
    nominal: NDArray
    lower: NDArray
    upper: NDArray
    sigma: dict[str, NDArray]
    sigma_source: str
    records: tuple[RunRecord, ...]
    bound: CramerRao
    summary: Summary
    data_sha256: str | None = None  # SHA-256 of the data file's bytes (None: simulated data)
    system: str = "vehicle"  # which system (systems.SYSTEMS) ran it: vehicle or damper
    findings: Any = None
    data_files: tuple[str, ...] = ()  # every measured run identified from (several: jointly); data_file names them
    objective: str = ""  # what a run's cost is (f1, f2, wls; J for a damper): System.objective_label
    channels: tuple[str, ...] = ()  # the measured channels of the records' channel_chi2
    checks: tuple[dict, ...] = ()  # the pre-fit checks' findings (SPEC section 6), measured data only
    warnings: tuple[str, ...] = ()  # what a user must know beyond the table (the checks', intervals', ...)
    stored_units: tuple[str, ...] = ()  # the units its file recorded, one per name (empty: an older file)

    @property
    def units(self) -> dict[str, str]:
        """{name: SI unit} of the unknowns: as the results file recorded them, else as the config declares them."""
        if len(self.stored_units) == len(self.names):
            return dict(zip(self.names, self.stored_units, strict=True))
        return self.config.units(self.names)

    @property
    def single_fit(self) -> bool:
        """One fit (measured data): every run would fit the same data, so there is no spread over runs."""
        return len(self.records) == 1

    def interval95(self) -> tuple[NDArray, NDArray]:
        """(centre, half-width) of each unknown's 95 % interval, in its unit. One fit: the estimate ± Z95 x the
        bound's sd at the estimate (already widened by sqrt(chi2) where the residual exceeds the noise); a
        campaign: the mean ± Z95 x the sd over runs (where one run's estimate falls). The half-width is NaN where
        no interval exists: one fit's estimate on a bound (the optimum lies beyond the box), an unidentifiable
        unknown (infinite sd)."""
        if not self.single_fit:
            return self.summary.mean, Z95 * self.summary.sd
        half = Z95 * np.asarray(self.bound.sd, dtype=float)
        half = np.where(np.isfinite(half), half, np.nan)
        for name in self.at_bound:
            half[self.names.index(name)] = np.nan
        return self.records[0].estimate, half

    @property
    def ci95(self) -> dict[str, list[float] | None]:
        """{name: [low, high]} of `interval95` (None where no interval exists)."""
        centre, half = self.interval95()
        return {
            n: [float(c - h), float(c + h)] if np.isfinite(h) else None
            for n, c, h in zip(self.names, centre, half, strict=True)
        }

    @property
    def at_bound(self) -> dict[str, int]:
        """Unknowns whose estimate sits on a bound of its search box, with in how many runs (an interval there means
        nothing: the optimum lies beyond the box)."""
        width = self.upper - self.lower
        out = {}
        for j, name in enumerate(self.names):
            hits = sum(
                bool(min(r.estimate[j] - self.lower[j], self.upper[j] - r.estimate[j]) <= BOUND_TOL * width[j])
                for r in self.records
            )  # fmt: skip
            if hits:
                out[name] = hits
        return out

    @property
    def per_channel(self) -> dict[str, dict[str, float]]:
        """Each measured channel's chi² per sample at the estimates (the median over runs)."""
        rows = [r.channel_chi2 for r in self.records if r.channel_chi2.size == len(self.channels)]
        if not rows or not self.channels:
            return {}
        with warnings.catch_warnings():  # a channel with no entries in any run: NaN, quietly
            warnings.simplefilter("ignore", RuntimeWarning)
            med = np.nanmedian(np.array(rows), axis=0)
        return {n: {"chi2_per_sample": float(v)} for n, v in zip(self.channels, med, strict=True)}

    def worst_channels(self, low: bool = False, count: int = 3) -> list[tuple[str, float]]:
        """The channels whose chi² per sample is farthest from 1 above (or, `low`, below), worst first."""
        pairs = [(n, d["chi2_per_sample"]) for n, d in self.per_channel.items() if np.isfinite(d["chi2_per_sample"])]
        pairs.sort(key=lambda p: p[1], reverse=not low)
        return pairs[:count]

    def advice(self) -> list[str]:
        """What a user must know about the campaign beyond its table, in plain words: an estimate on its bound, a
        residual far from the noise (either side) with the channels that make it, what the sensors cannot identify,
        evaluations that got the penalty."""
        s, out = self.summary, []
        runs = len(self.records)
        for name, hits in self.at_bound.items():
            where = "" if runs == 1 else f" in {hits} of {runs} runs"
            j = self.names.index(name)
            box = f"[{self.lower[j]:.4g}, {self.upper[j]:.4g}] {self.units[name]}".rstrip()
            out.append(
                f"{name} sits on a bound of its search box {box}{where}: the optimum lies beyond it and no interval "
                "means anything there; widen identify.bounds or identify.limits, or check the data (vehid check)"
            )
        low_limit = 1.0 - 5.0 * np.sqrt(2.0 / max(s.residual_samples, 1))
        if s.model_inadequate:
            worst = ", ".join(f"{n} {v:.3g}" for n, v in self.worst_channels())
            out.append(
                f"at the estimates the residual power is {s.chi2_median:.3g} times the noise power the data implies "
                f"(an adequate model gives at most {s.chi2_limit:.3g}, noise from {self.sigma_source}): the model "
                "lacks something, the measurement chain is wrong or the noise is understated; the estimates are then "
                "biased" + (f"; worst channels (chi2 per sample): {worst}" if worst else "")
            )
        elif np.isfinite(s.chi2_median) and s.chi2_median < low_limit:
            lowest = ", ".join(f"{n} {v:.3g}" for n, v in self.worst_channels(low=True))
            out.append(
                f"at the estimates the residual power is only {s.chi2_median:.3g} times the assumed noise power (noise "
                f"from {self.sigma_source}): the noise is overstated, so the intervals are too wide"
                + (f"; lowest channels (chi2 per sample): {lowest}" if lowest else "")
            )
        unidentifiable = self.bound.unidentifiable()
        if unidentifiable:
            out.append(f"the sensors cannot identify {', '.join(unidentifiable)} (Fisher information)")
        return out

    def to_json(self) -> dict:
        """SPEC section 5 `identify` object (plus a few extra keys); strict JSON once through `core.jsonio`."""
        s, b, names = self.summary, self.bound, list(self.names)

        def obj(values):
            return None if values is None else {n: finite_or_none(v) for n, v in zip(names, values, strict=True)}

        evals = [int(e) for e in s.evaluations]
        return {
            "parameters": names,
            "truth": obj(self.truth),
            "mean": obj(s.mean),
            "re_percent": obj(s.re_percent),
            "nre_percent": s.nre_percent,
            "per_run_nre_percent": None if s.per_run_nre_percent is None else [float(v) for v in s.per_run_nre_percent],
            "units": self.units,
            "ci95": self.ci95,
            "ci95_from": "bound" if self.single_fit else "runs",
            "crlb": {
                "re_sd_percent": obj(b.re_sd_percent),
                "sd": obj(b.sd),
                "nre_rms_percent": finite_or_none(b.nre_rms_percent),
                "unidentifiable": b.unidentifiable(),
            },
            "evaluations_per_run": float(np.mean(evals)),
            "runs": len(self.records),
            "wall_s": s.wall_s,
            "per_run_nre_median": s.per_run_nre_median,
            "per_run_nre_rms": s.per_run_nre_rms,
            "nre_over_crlb": s.nre_over_crlb,
            "evaluations": evals,
            "penalised_evaluations": s.penalised,
            "runs_at_penalty": s.at_penalty,
            "converged_runs": s.converged,
            "chi2_per_sample": s.chi2_median,
            "model_inadequate": s.model_inadequate,
            "objective": self.objective,
            "algorithm": self.config.identify.algorithm.name,
            "noise_level": self.config.noise.level,
            "system": self.system,
            "at_bound": list(self.at_bound),
            "per_channel": {n: {k: finite_or_none(v) for k, v in d.items()} for n, d in self.per_channel.items()},
            "checks": [dict(c) for c in self.checks],
            "warnings": list(self.warnings) + self.advice(),
            **({} if self.findings is None else self.findings.json_keys(self)),
        }
