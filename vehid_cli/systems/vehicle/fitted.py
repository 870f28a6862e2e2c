"""Measured against fitted, per channel: what an engineer looks at first after a fit on measured data. The model is
simulated at the estimate (not the configured car), and each channel's residual is set against the noise the fit
assumes, in time and in frequency (Welch's amplitude spectral density against the white-noise floor of its sigma)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ...core.errors import InputError
from ...diagnose.residuals import residual_spectrum
from ...identify.records import worst_first
from ...identify.source import DataSource
from ...identify.task import JointTask, Task, build_tasks
from ...models.sensors import UNIT


@dataclass(frozen=True)
class ChannelFit:
    """One measured channel at its own samples: the data, the fitted model and their difference, in SI units
    (`unit`), with the noise sigma the fit assumes and the residual's amplitude spectral density."""

    name: str
    family: str
    unit: str  # SI unit of measured, fitted, residual and sigma (m, m/s^2)
    t: NDArray  # (m,) [s]: the channel's own sample times
    measured: NDArray  # (m,) as the fit saw it (offsets removed as configured)
    fitted: NDArray  # (m,) the model at the estimate (plus the channel's profiled offset, when offsets are unknowns)
    residual: NDArray  # (m,) measured - fitted
    sigma: float  # noise standard deviation the fit assumes [unit]
    freq: NDArray  # (nf,) [Hz]
    asd: NDArray  # (nf,) residual amplitude spectral density [unit/sqrt(Hz)]
    floor: float  # the white-noise ASD of sigma [unit/sqrt(Hz)]: sqrt(2 sigma^2 / fs), one-sided

    @property
    def chi2_per_sample(self) -> float:
        """Mean squared residual over sigma² (about 1 for a model that fits to the noise)."""
        return float(np.mean((self.residual / self.sigma) ** 2)) if self.sigma > 0 else float("inf")


def fitted_channels(task: Task, estimate: NDArray) -> list[ChannelFit]:
    """Every channel of the objective's families, measured against the model at `estimate` (the task's unknowns,
    in order): a slow channel at its own samples, a profiled offset added to the model, sensor corrections among the
    unknowns applied, as in the fit itself."""
    reference = task.measured if task.measured is not None else task.reference(0)
    objective = task.objective({f: reference[f] for f in task.families})
    model = task.outputs({n: np.array([v]) for n, v in zip(task.names, estimate, strict=True)})
    t = task.experiment.t
    out = []
    for family in task.families:
        sim = model[family][0]
        residual = objective.error(family, sim.copy())
        for k, name in enumerate(task.experiment.layout.names(family)):
            own = np.ones(t.size, dtype=bool) if task.observed is None else task.observed[family][:, k]
            tk, r = t[own], residual[own, k]
            fs = 1.0 / float(np.median(np.diff(tk)))
            sigma = float(task.sigma[family][k])
            freq, asd = residual_spectrum(r, fs)
            y = reference[family][own, k]
            out.append(ChannelFit(
                name=name, family=family, unit=UNIT[family], t=tk, measured=y, fitted=y - r, residual=r,
                sigma=sigma, freq=freq, asd=asd, floor=float(np.sqrt(2.0 * sigma**2 / fs)),
            ))  # fmt: skip
    return out


def campaign_fits(campaign) -> list[tuple[str, list[ChannelFit]]]:
    """A measured-data campaign's channels against its (first run's) estimate, per measured run (label, channels),
    each run's channels worst first (chi² per sample of the fit)."""
    files = campaign.data_files or (() if campaign.data_file is None else (campaign.data_file,))
    digest = DataSource.resolve(campaign.config, files).digest
    if campaign.data_sha256 and digest != campaign.data_sha256:
        raise InputError(
            "has changed since the campaign was fitted to it (SHA-256 differs): measured against fitted would compare "
            "other data; restore the file or identify again", source=" + ".join(files),
        )  # fmt: skip
    built = build_tasks(campaign.config, files)
    tasks = built.tasks if isinstance(built, JointTask) else (built,)
    estimate = campaign.records[0].estimate
    out = []
    for task, label in zip(tasks, files or ("simulated",), strict=False):
        fits = fitted_channels(task, estimate)
        order = worst_first({f.name: f.chi2_per_sample for f in fits})
        out.append((str(label), sorted(fits, key=lambda f: order.index(f.name))))
    return out
