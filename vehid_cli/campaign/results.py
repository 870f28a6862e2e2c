"""Campaign files: one layout for every system (a `system` attribute, a group for what the system concluded),
provenance, reading back, and how a stored campaign differs from a config; written through the checksummed store
(`core.store`)."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

import h5py
import numpy as np
import yaml

from ..config import config_from_dict, flatten
from ..core.errors import InputError
from ..core.provenance import provenance
from ..core.store import USERBLOCK, checksum_block, h5_file, open_results
from ..identify.crlb import CramerRao
from ..identify.records import Campaign, RunRecord, summarise
from ..systems import SYSTEMS

# ------------------------------------------------------------------------------------------ campaigns

CAMPAIGN_KIND = "vehid.campaign"


def _padded(rows: list[np.ndarray], fill: float) -> np.ndarray:
    width = max((r.size for r in rows), default=0)
    out = np.full((len(rows), width), fill, dtype=float)
    for i, r in enumerate(rows):
        out[i, : r.size] = r
    return out


SEED_SCHEME = (
    "numpy PCG64 streams of run i (0-based): (noise, optimizer) = SeedSequence(seed).spawn(2)[1].spawn(i + 1)[i]"
    ".spawn(2); the experiment's own stream (random road) is SeedSequence(seed).spawn(2)[0]"
)


def write_campaign_h5(path: str | Path, campaign, attrs: Mapping[str, str] | None = None) -> None:
    """One campaign of any system in one file, written atomically. Layout (README, "Campaign files"):

    attrs: kind, system (vehicle, damper), config_yaml, config_sha256, seed, runs, objective (f1, f2, wls; J for
    a damper), algorithm, data_file, data_sha256, sigma_source, provenance, `attrs` (e.g. a sweep's varied keys);
    the user block holds the file's checksum
    /parameters (D,) names; /truth (D,) (NaN when unknown; attr known); /nominal, /bounds (D, 2)
    /runs/{estimate (N, D), cost, evaluations, penalised, wall_s (N,), history_evals, history_cost (N, H)}
    /summary/{mean, sd, re_percent, per_run_nre_percent, ...} with scalar figures as attributes
    /crlb/{re_sd_percent (D,), fisher (D, D), identifiable (D,)} with nre_rms_percent, condition attributes
    /noise_sigma/<family> (4,) noise standard deviation per channel used by wls and the bound (a damper: force (1,))
    /runs/initial_cost (N,): the cost at the start (a damper fit's J before; NaN when not recorded)
    /<system>/...: what the system concluded after the runs (a damper: model_names, model_values, validation/{files,
    J}, realtime attrs, traces/<k>/{t, x, v, measured, model} with attrs name, J)
    """
    with h5_file(path, userblock=USERBLOCK, head=checksum_block) as h5:
        _write_campaign(h5, campaign, attrs)


def _write_campaign(h5: h5py.File, campaign, attrs: Mapping[str, str] | None) -> None:
    cfg, s, b = campaign.config, campaign.summary, campaign.bound
    D = len(campaign.names)
    h5.attrs["kind"] = CAMPAIGN_KIND
    h5.attrs["system"] = campaign.system
    h5.attrs["config_yaml"] = cfg.to_yaml()
    h5.attrs["config_sha256"] = cfg.digest()
    h5.attrs["seed"] = cfg.identify.seed
    h5.attrs["seed_scheme"] = SEED_SCHEME
    h5.attrs["runs"] = len(campaign.records)
    h5.attrs["objective"] = campaign.objective
    h5.attrs["algorithm"] = cfg.identify.algorithm.name
    for key, value in SYSTEMS[campaign.system].results_attributes(cfg).items():  # the car's sensors, a damper's model
        h5.attrs[key] = value
    h5.attrs["noise_level"] = cfg.noise.level
    h5.attrs["data_file"] = campaign.data_file or ""
    h5.attrs["data_sha256"] = campaign.data_sha256 or ""
    h5.attrs["data_files"] = json.dumps(list(campaign.data_files))
    h5.attrs["sigma_source"] = campaign.sigma_source
    for key, value in provenance().items():
        h5.attrs[key] = value
    for key, value in (attrs or {}).items():
        h5.attrs[key] = value
    h5.create_dataset("parameters", data=np.array(campaign.names, dtype=h5py.string_dtype()))
    truth = h5.create_dataset("truth", data=campaign.truth if campaign.truth is not None else np.full(D, np.nan))
    truth.attrs["known"] = campaign.truth is not None
    h5.create_dataset("nominal", data=campaign.nominal)
    h5.create_dataset("bounds", data=np.column_stack([campaign.lower, campaign.upper]))
    runs = h5.create_group("runs")
    recs = campaign.records
    runs.create_dataset("estimate", data=np.array([r.estimate for r in recs]))
    runs.create_dataset("cost", data=np.array([r.cost for r in recs]))
    runs.create_dataset("evaluations", data=np.array([r.evaluations for r in recs]))
    runs.create_dataset("penalised", data=np.array([r.penalised for r in recs]))
    runs.create_dataset("wall_s", data=np.array([r.wall_s for r in recs]))
    runs.create_dataset("truth_cost", data=np.array([r.truth_cost for r in recs]))
    runs.create_dataset("chi2", data=np.array([r.chi2 for r in recs]))
    runs.create_dataset("initial_cost", data=np.array([r.initial_cost for r in recs]))
    if campaign.channels:
        chi2 = np.array([r.channel_chi2 if r.channel_chi2.size == len(campaign.channels) else
                         np.full(len(campaign.channels), np.nan) for r in recs])  # fmt: skip
        runs.create_dataset("channel_chi2", data=chi2).attrs["channels"] = json.dumps(list(campaign.channels))
    h5.attrs["checks"] = json.dumps(list(campaign.checks))
    h5.attrs["warnings"] = json.dumps(list(campaign.warnings))
    runs.create_dataset("history_evals", data=_padded([r.history_evals for r in recs], -1).astype(np.int64))
    runs.create_dataset("history_cost", data=_padded([r.history_cost for r in recs], np.nan))
    sg = h5.create_group("summary")
    sg.create_dataset("mean", data=s.mean)
    sg.create_dataset("sd", data=s.sd)
    if s.re_percent is not None:
        sg.create_dataset("re_percent", data=s.re_percent)
        sg.create_dataset("per_run_nre_percent", data=s.per_run_nre_percent)
        sg.attrs["nre_percent"] = s.nre_percent
        sg.attrs["per_run_nre_median"] = s.per_run_nre_median
        sg.attrs["per_run_nre_rms"] = s.per_run_nre_rms
    if s.nre_over_crlb is not None:
        sg.attrs["nre_over_crlb"] = s.nre_over_crlb
    if s.converged is not None:
        sg.attrs["converged_runs"] = s.converged
    sg.attrs["chi2_median"] = s.chi2_median
    sg.attrs["residual_samples"] = s.residual_samples
    sg.attrs["wall_s"] = s.wall_s
    sg.attrs["penalised"] = s.penalised
    cg = h5.create_group("crlb")
    cg.create_dataset("re_sd_percent", data=b.re_sd_percent)
    cg.create_dataset("fisher", data=b.fisher)
    cg.create_dataset("identifiable", data=b.identifiable)
    cg.attrs["nre_rms_percent"] = b.nre_rms_percent
    cg.attrs["condition"] = b.condition
    ng = h5.create_group("noise_sigma")
    for family, sigma in campaign.sigma.items():
        ng.create_dataset(family, data=sigma)
    if campaign.findings is not None:
        campaign.findings.write_h5(h5.create_group(campaign.system))


def read_campaign_h5(path: str | Path):
    """Read a campaign file back into a `Campaign` (raises InputError for a file that is not one)."""
    source = str(path)
    with open_results(path, CAMPAIGN_KIND, "campaign file") as h5:
        try:
            config = config_from_dict(yaml.safe_load(h5.attrs["config_yaml"]), source=f"{source}:config_yaml")
            names = tuple(n.decode() if isinstance(n, bytes) else str(n) for n in h5["parameters"][()])
            truth = h5["truth"][()] if h5["truth"].attrs["known"] else None
            runs = h5["runs"]
            est, cost, evals = runs["estimate"][()], runs["cost"][()], runs["evaluations"][()]
            pen, wall = runs["penalised"][()], runs["wall_s"][()]
            tcost = runs["truth_cost"][()]
            chi2 = runs["chi2"][()]
            initial = runs["initial_cost"][()] if "initial_cost" in runs else np.full(len(est), np.nan)
            channel_chi2 = runs["channel_chi2"][()] if "channel_chi2" in runs else np.zeros((len(est), 0))
            channels = tuple(json.loads(runs["channel_chi2"].attrs["channels"])) if "channel_chi2" in runs else ()
            hev, hco = runs["history_evals"][()], runs["history_cost"][()]
            records = tuple(
                RunRecord(
                    index=i,
                    estimate=est[i],
                    cost=float(cost[i]),
                    evaluations=int(evals[i]),
                    penalised=int(pen[i]),
                    wall_s=float(wall[i]),
                    history_evals=hev[i][hev[i] >= 0],
                    history_cost=hco[i][~np.isnan(hco[i])],
                    truth_cost=float(tcost[i]),
                    chi2=float(chi2[i]),
                    initial_cost=float(initial[i]),
                    channel_chi2=channel_chi2[i],
                )
                for i in range(len(est))
            )
            cg = h5["crlb"]
            bound = CramerRao(
                names=names,
                values=truth if truth is not None else h5["nominal"][()],
                fisher=cg["fisher"][()],
                re_sd_percent=cg["re_sd_percent"][()],
                nre_rms_percent=float(cg.attrs["nre_rms_percent"]),
                identifiable=cg["identifiable"][()],
                condition=float(cg.attrs["condition"]),
            )
            summary = summarise(
                names, truth, list(records), bound, float(h5["summary"].attrs["wall_s"]),
                int(h5["summary"].attrs["residual_samples"]),
            )  # fmt: skip
            bounds = h5["bounds"][()]
            sigma = {k: h5["noise_sigma"][k][()] for k in h5["noise_sigma"]}
            system = str(h5.attrs.get("system", "vehicle"))
            if system not in SYSTEMS:
                raise ValueError(f"unknown system {system!r}")
            kind = SYSTEMS[system].findings_type
            findings = None if kind is None else kind.read_h5(h5[system])
            return Campaign(
                config=config, data_file=h5.attrs["data_file"] or None, names=names, truth=truth,
                nominal=h5["nominal"][()], lower=bounds[:, 0], upper=bounds[:, 1], sigma=sigma,
                sigma_source=str(h5.attrs["sigma_source"]), records=records, bound=bound, summary=summary,
                data_sha256=str(h5.attrs.get("data_sha256", "")) or None, system=system, findings=findings,
                data_files=tuple(json.loads(str(h5.attrs.get("data_files", "[]")))),
                objective=str(h5.attrs["objective"]), channels=channels,
                checks=tuple(json.loads(str(h5.attrs.get("checks", "[]")))),
                warnings=tuple(json.loads(str(h5.attrs.get("warnings", "[]")))),
            )  # fmt: skip
        except (KeyError, ValueError, TypeError, OSError, RuntimeError, yaml.YAMLError) as exc:  # reactions to damage
            raise InputError(f"campaign file is damaged or incomplete ({exc})", source=source) from None


def campaign_file_digest(path: str | Path) -> str:
    """The config digest of a whole, undamaged campaign file (InputError for a damaged or foreign one): what a
    sweep compares before it skips a campaign as up to date."""
    source = str(path)
    with open_results(path, CAMPAIGN_KIND, "campaign file") as h5:
        try:
            return str(h5.attrs["config_sha256"])
        except (KeyError, OSError, RuntimeError) as exc:
            raise InputError(f"campaign file is damaged or incomplete ({exc})", source=source) from None


def config_difference(path: str | Path, config, data_sha256: str | None) -> list[str]:
    """How the campaign stored in `path` differs from `config` (and the data file's SHA-256): dotted keys with
    both values, or the data file; [] when it is the same campaign. InputError for a damaged or foreign file."""
    source = str(path)
    with open_results(path, CAMPAIGN_KIND, "campaign file") as h5:
        try:
            stored = yaml.safe_load(str(h5.attrs["config_yaml"]))
            stored_data = str(h5.attrs.get("data_sha256", "")) or None
        except (KeyError, OSError, RuntimeError, yaml.YAMLError) as exc:
            raise InputError(f"campaign file is damaged or incomplete ({exc})", source=source) from None
    mine = flatten(yaml.safe_load(config.to_yaml()))
    theirs = flatten(stored if isinstance(stored, dict) else {})
    diffs = [
        f"{k}: {theirs.get(k, '(absent)')!r} in the file, {mine.get(k, '(absent)')!r} now"
        for k in sorted(set(mine) | set(theirs))
        if mine.get(k, "(absent)") != theirs.get(k, "(absent)")
    ]
    if stored_data != data_sha256:
        diffs.append("the data file's bytes (SHA-256) differ")
    return diffs
