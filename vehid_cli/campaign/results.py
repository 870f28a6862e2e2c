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
from ..core.errors import InputError, quote
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
    /parameters (D,) names (attribute units: a JSON list, the SI unit of each)
    /truth (D,) (NaN when unknown; attr known); /nominal, /bounds (D, 2)
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
    parameters = h5.create_dataset("parameters", data=np.array(campaign.names, dtype=h5py.string_dtype()))
    parameters.attrs["units"] = json.dumps(list(campaign.units.values()))  # SI unit of each, in order
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


class _Reader:
    """What a campaign file holds, each part checked before it is trusted (type, shape, finiteness): a checksum
    proves the bytes are the ones written, not that their content is sane. Every failure is an InputError naming
    the file and the part."""

    def __init__(self, h5, source: str):
        self.h5, self.source = h5, source

    def fail(self, part: str, what: str) -> InputError:
        return InputError(f"campaign file is damaged or was edited: {part} {what}", source=self.source)

    def text(self, name: str, default: str | None = None) -> str:
        value = self.h5.attrs.get(name, default)
        if value is None:
            raise self.fail(f"attribute '{name}'", "is missing")
        if not isinstance(value, str):
            raise self.fail(f"attribute '{name}'", f"should be text, found {quote(value, 80)}")
        return value

    def number(self, group, name: str, integer: bool = False) -> float:
        value = group.attrs.get(name)
        where = f"attribute '{name}' of {group.where}"
        if isinstance(value, np.ndarray) and value.shape in ((), (1,)):
            value = value.reshape(())[()]
        if value is None or isinstance(value, (str, bytes)) or not isinstance(value, (int, float, np.number, bool)):
            raise self.fail(where, f"should be a number, found {quote(value, 80)}")
        if integer and (not np.isfinite(value) or value != int(value)):
            raise self.fail(where, f"should be a whole number, found {quote(value, 80)}")
        return int(value) if integer else float(value)

    def json_list(self, name: str, item: type) -> list:
        text = self.text(name, "[]")
        try:
            value = json.loads(text)
        except (ValueError, RecursionError):
            raise self.fail(f"attribute '{name}'", f"is not JSON: {quote(text, 80)}") from None
        if not isinstance(value, list) or not all(isinstance(v, item) for v in value):
            raise self.fail(f"attribute '{name}'", f"should be a JSON list of {item.__name__}, found {quote(text, 80)}")
        return value

    def array(self, path: str, shape: tuple, kinds: str = "f", finite: bool = False) -> np.ndarray:
        """The dataset at `path` with this shape (None: any length) and a dtype of these kinds."""
        try:
            node = self.h5[path]
        except KeyError:
            raise self.fail(f"dataset '{path}'", "is missing") from None
        if not hasattr(node, "array"):
            raise self.fail(f"'{path}'", "is a group, expected a dataset")
        a = node.array
        if a.dtype.kind not in kinds or (kinds == "O" and not all(isinstance(v, str) for v in a.ravel())):
            raise self.fail(f"dataset '{path}'", f"has type {a.dtype}, expected {KINDS[kinds]}")
        if a.ndim != len(shape) or any(n is not None and n != m for n, m in zip(shape, a.shape, strict=True)):
            want = "(" + ", ".join("any" if n is None else str(n) for n in shape) + ")"
            raise self.fail(f"dataset '{path}'", f"has shape {a.shape}, expected {want}")
        if finite and a.dtype.kind in "fiub" and not np.isfinite(a.astype(float)).all():
            raise self.fail(f"dataset '{path}'", "holds NaN or infinite values")
        return a.astype(float) if kinds == "fiub" or kinds == "f" else a


def stored_attributes(h5, source: str) -> _Reader:
    """A checked reader of a campaign file's parts (`text`, `number`, `json_list`, `array`) for other modules."""
    return _Reader(h5, source)


KINDS = {"f": "floating-point numbers", "fiub": "numbers", "iu": "integers", "O": "text", "biuf": "numbers"}


def stored_yaml(text: str, source: str, limit: int = 1 << 20):
    """A config stored in a file (a campaign's config_yaml) parsed without trusting it: at most `limit`
    characters, no YAML aliases (vehid never writes them; a few hundred bytes of them expand exponentially), at most
    64 levels deep; InputError naming the file otherwise."""
    if len(text) > limit:
        raise InputError(f"config_yaml is {len(text)} characters, more than a config holds ({limit})", source=source)
    try:
        depth = 0
        for event in yaml.parse(text, Loader=yaml.SafeLoader):
            if isinstance(event, yaml.AliasEvent):
                raise InputError("config_yaml uses YAML aliases, which vehid never writes (edited?)", source=source)
            if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
                depth += 1
                if depth > 64:
                    raise InputError("config_yaml is nested more than 64 levels deep", source=source)
            elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
                depth -= 1
        return yaml.safe_load(text)
    except (yaml.YAMLError, ValueError, RecursionError) as exc:
        raise InputError(f"config_yaml is not readable YAML ({quote(str(exc), 160)})", source=source) from None


def _records(r: _Reader, D: int) -> tuple[tuple[RunRecord, ...], tuple[str, ...]]:
    """The run records, every dataset of /runs checked against the number of runs and of unknowns."""
    est = r.array("runs/estimate", (None, D), finite=True)
    N = est.shape[0]
    if N < 1:
        raise r.fail("dataset 'runs/estimate'", "holds no run")
    one = {k: r.array(f"runs/{k}", (N,), "fiub") for k in ("cost", "penalised", "wall_s", "truth_cost", "chi2")}
    evals = r.array("runs/evaluations", (N,), "iu")
    initial = r.array("runs/initial_cost", (N,), "fiub") if "runs/initial_cost" in r.h5 else np.full(N, np.nan)
    channels: tuple[str, ...] = ()
    channel_chi2 = np.zeros((N, 0))
    if "runs/channel_chi2" in r.h5:
        node = r.h5["runs/channel_chi2"]
        attrs = _Reader(node, r.source)
        channels = tuple(attrs.json_list("channels", str))
        channel_chi2 = r.array("runs/channel_chi2", (N, len(channels)), "fiub")
    hev = r.array("runs/history_evals", (N, None), "iu")
    hco = r.array("runs/history_cost", (N, hev.shape[1]), "fiub")
    if (evals < 0).any() or (one["penalised"] < 0).any() or not np.isfinite(one["penalised"]).all():
        raise r.fail("datasets 'runs/evaluations' and 'runs/penalised'", "should hold counts (whole numbers >= 0)")
    records = tuple(
        RunRecord(
            index=i, estimate=est[i], cost=float(one["cost"][i]), evaluations=int(evals[i]),
            penalised=int(one["penalised"][i]), wall_s=float(one["wall_s"][i]),
            history_evals=hev[i][hev[i] >= 0], history_cost=hco[i][~np.isnan(hco[i])],
            truth_cost=float(one["truth_cost"][i]), chi2=float(one["chi2"][i]), initial_cost=float(initial[i]),
            channel_chi2=channel_chi2[i],
        )
        for i in range(N)
    )  # fmt: skip
    return records, channels


def _box(r: _Reader) -> tuple[tuple[str, ...], np.ndarray | None, np.ndarray, np.ndarray]:
    """(names, truth or None, nominal, bounds) of the stored unknowns, checked."""
    names = tuple(r.array("parameters", (None,), "O"))
    D = len(names)
    if D < 1 or len(set(names)) != D:
        raise r.fail("dataset 'parameters'", f"should name distinct unknowns, found {quote(names, 120)}")
    known = r.h5["truth"].attrs.get("known") if "truth" in r.h5 else None
    if not isinstance(known, (bool, np.bool_, int, np.integer)):
        raise r.fail("attribute 'known' of /truth", f"should be true or false, found {quote(known, 80)}")
    truth = r.array("truth", (D,), "fiub", finite=bool(known)) if known else None
    if truth is not None and (truth == 0).any():
        raise r.fail("dataset 'truth'", "holds a zero (relative errors need a nonzero truth)")
    nominal = r.array("nominal", (D,), "fiub", finite=True)
    bounds = r.array("bounds", (D, 2), "fiub", finite=True)
    if not (bounds[:, 0] < bounds[:, 1]).all():
        raise r.fail("dataset 'bounds'", "should hold a lower bound below the upper one for every unknown")
    return names, truth, nominal, bounds


def _bound(r: _Reader, names, values) -> CramerRao:
    D = len(names)
    cg = r.h5["crlb"] if "crlb" in r.h5 else None
    if cg is None or not hasattr(cg, "members"):
        raise r.fail("group '/crlb'", "is missing")
    return CramerRao(
        names=names, values=values, fisher=r.array("crlb/fisher", (D, D), "fiub"),
        re_sd_percent=r.array("crlb/re_sd_percent", (D,), "fiub"),
        nre_rms_percent=r.number(cg, "nre_rms_percent"), identifiable=r.array("crlb/identifiable", (D,), "biuf") != 0,
        condition=r.number(cg, "condition"),
    )  # fmt: skip


def _sigma(r: _Reader) -> dict[str, np.ndarray]:
    group = r.h5["noise_sigma"] if "noise_sigma" in r.h5 else None
    if group is None or not hasattr(group, "members"):
        raise r.fail("group '/noise_sigma'", "is missing")
    return {k: r.array(f"noise_sigma/{k}", (None,), "fiub") for k in group}


def read_campaign_h5(path: str | Path):
    """Read a campaign file back into a `Campaign` (raises InputError for a file that is not one, or whose content
    is not what vehid writes: every part is checked before it is trusted)."""
    source = str(path)
    with open_results(path, CAMPAIGN_KIND, "campaign file") as h5:
        r = _Reader(h5, source)
        raw = stored_yaml(r.text("config_yaml"), source)
        if not isinstance(raw, dict):
            raise r.fail("attribute 'config_yaml'", "should hold a config (a mapping)")
        config = config_from_dict(raw, source=f"{source}:config_yaml")
        names, truth, nominal, bounds = _box(r)
        records, channels = _records(r, len(names))
        # the bound's relative sd is about where it was computed: the truth, else one fit's estimate (runner)
        at = truth if truth is not None else records[0].estimate if len(records) == 1 else nominal
        bound = _bound(r, names, at)
        summary_group = h5["summary"] if "summary" in h5 else None
        if summary_group is None or not hasattr(summary_group, "members"):
            raise r.fail("group '/summary'", "is missing")
        samples = r.number(summary_group, "residual_samples", integer=True)
        summary = summarise(names, truth, list(records), bound, r.number(summary_group, "wall_s"), max(samples, 0))
        system = r.text("system", "vehicle")
        if system not in SYSTEMS:
            raise r.fail("attribute 'system'", f"names no system vehid knows: {quote(system, 80)}")
        if system != config.system:
            raise r.fail("attribute 'system'", f"says {system} but its config is of a {config.system}")
        kind = SYSTEMS[system].findings_type
        try:
            findings = None if kind is None else kind.read_h5(h5[system])
        except (KeyError, ValueError, TypeError, IndexError) as exc:
            raise r.fail(f"group '/{system}'", f"is incomplete ({quote(str(exc), 120)})") from None
        return Campaign(
            config=config, data_file=r.text("data_file") or None, names=names, truth=truth, nominal=nominal,
            lower=bounds[:, 0], upper=bounds[:, 1], sigma=_sigma(r), sigma_source=r.text("sigma_source"),
            records=records, bound=bound, summary=summary, data_sha256=r.text("data_sha256", "") or None,
            system=system, findings=findings, data_files=tuple(r.json_list("data_files", str)),
            objective=r.text("objective"), channels=channels, checks=tuple(r.json_list("checks", dict)),
            warnings=tuple(r.json_list("warnings", str)), stored_units=_units(h5, source, len(names)),
        )  # fmt: skip


def _units(h5, source: str, D: int) -> tuple[str, ...]:
    """The unit of each unknown as the file recorded it (/parameters attribute `units`); () for a file written
    before units were recorded (the config's declarations then give them)."""
    units = _Reader(h5["parameters"], source).json_list("units", str)
    if units and len(units) != D:
        raise InputError(f"campaign file is damaged or was edited: attribute 'units' of /parameters names "
                         f"{len(units)} units for {D} unknowns", source=source)  # fmt: skip
    return tuple(units)


def campaign_file_digest(path: str | Path) -> str:
    """The config digest of a whole, undamaged campaign file (InputError for a damaged or foreign one): what a
    sweep compares before it skips a campaign as up to date."""
    source = str(path)
    with open_results(path, CAMPAIGN_KIND, "campaign file") as h5:
        return _Reader(h5, source).text("config_sha256")


def config_difference(path: str | Path, config, data_sha256: str | None) -> list[str]:
    """How the campaign stored in `path` differs from `config` (and the data file's SHA-256): dotted keys with
    both values, or the data file; [] when it is the same campaign. InputError for a damaged or foreign file."""
    source = str(path)
    with open_results(path, CAMPAIGN_KIND, "campaign file") as h5:
        r = _Reader(h5, source)
        stored = stored_yaml(r.text("config_yaml"), source)
        stored_data = r.text("data_sha256", "") or None
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
