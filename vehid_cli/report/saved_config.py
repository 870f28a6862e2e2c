"""What `identify` and `diagnose` found, as `config.save.Identified` for `--save-config`: the campaign's estimate
(one fit's, or the mean over runs) or the diagnosis's final model, with 95 % intervals and where they came from."""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from ..config.save import Identified
from ..identify.corrections import is_sensor_unknown
from ..identify.records import Campaign


def _now() -> str:
    return datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")  # noqa: UP017


def _label(files: Sequence[str | Path]) -> str:
    """The run in a few words: the data files' names (or simulated data) and today's date."""
    data = " + ".join(Path(f).name for f in files) or "simulated data"
    return f"{data}, {_now()[:10]}"


def campaign_found(campaign: Campaign, results_file: str | Path | None = None) -> Identified:
    """One fit (measured data, or a single run): the estimate, its interval 1.96 x the bound's sd at it (widened when
    the residual is not noise); several runs: the mean, its interval t(0.975, N - 1) x sd / sqrt(N)."""
    from scipy.stats import t as student

    s, runs = campaign.summary, len(campaign.records)
    if runs == 1:
        half = 1.96 * np.asarray(campaign.bound.sd, dtype=float)
        what, at_bound = "one fit", tuple(campaign.at_bound)
    else:
        half = float(student.ppf(0.975, runs - 1)) * s.sd / np.sqrt(runs)
        what, at_bound = f"the mean of {runs} runs (interval of the mean)", ()
    files = campaign.data_files or ((campaign.data_file,) if campaign.data_file else ())
    data = f"data {' + '.join(Path(f).name for f in files)}" if files else "simulated data"
    where = f" -> {results_file}" if results_file is not None else ""
    values, ci = {}, {}
    for j, name in enumerate(campaign.names):
        if is_sensor_unknown(name):  # the measurement chain's, not the car's: data.invert, data.units, ... say it
            continue
        values[name] = float(s.mean[j])
        ci[name] = (float(s.mean[j] - half[j]), float(s.mean[j] + half[j])) if np.isfinite(half[j]) else None
    return Identified(values, ci, f"vehid identify, {what} on {data}{where}, {_now()}", at_bound, _label(files))


def diagnosis_found(result, data: Sequence[str | Path]) -> Identified:
    """The diagnosis's final model (`result.after`): every estimate (declared unknowns, freed parameters, the
    selected effects' parameters, shape parameters held fixed included) with its interval (none where fixed), which
    assumes the model right; where the model is wrong the comments add, marked, the interval surviving the misfit
    (`ci_misfit`) and the one covering the model uncertainty (library terms imitating a law)."""
    after = result.after
    misfit = getattr(after, "ci_misfit", None)
    mu = getattr(result, "model_uncertainty", None)
    imitates = mu is not None and mu.imitates
    widened = {n: (lo, hi) for n, lo, hi in zip(mu.names, mu.low, mu.high, strict=True)} if imitates else {}
    values, ci, notes = {}, {}, {}
    for j, (name, x, h) in enumerate(zip(after.names, after.x, after.ci, strict=True)):
        if is_sensor_unknown(name):
            continue
        values[name] = float(x)
        ci[name] = (float(x - h), float(x + h)) if np.isfinite(h) else None
        other = []
        if ci[name] is not None:
            other.append("assuming the model right")
        if misfit is not None and np.isfinite(misfit[j]):
            other.append(f"surviving the misfit [{x - misfit[j]:.6g}, {x + misfit[j]:.6g}]")
        if name in widened:
            lo, hi = widened[name]
            other.append(f"covering the model uncertainty (library terms imitate a law) [{lo:.6g}, {hi:.6g}]")
        if len(other) > 1:
            notes[name] = "; ".join(other)
    selected = ", ".join(result.selected) or "nothing"
    runs = " + ".join(Path(f).name for f in data) or "the config's data"
    return Identified(values, ci, f"vehid diagnose on {runs} (selected: {selected}), {_now()}", (), _label(data),
                      notes)  # fmt: skip
