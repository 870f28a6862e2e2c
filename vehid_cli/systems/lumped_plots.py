"""The figures of a linear rig: `vehid simulate --plot` (the inputs, then every channel measured over the configured
rig's clean response) and `vehid report --plots` (per campaign and run, every channel measured against the rig at
the first run's estimate, with the residual against the noise's ±1 sigma band)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..core.figures import plt, save
from ..identify.source import DataSource

AXES = {"disp": ("mm", 1e3), "acc": ("m/s²", 1.0)}  # the unit each family is drawn in, and its scale from SI


@dataclass(frozen=True)
class RigTrace:
    """One run of a rig as drawn: its inputs and, per channel, the data beside the model."""

    t: NDArray  # (n,) [s]
    inputs: dict[str, NDArray]  # input name -> (n,) [m or N]
    channels: tuple[tuple[str, str, NDArray, NDArray, float], ...]  # (name, family, data, model, sigma) [SI]


def trace(system, run: int, data: dict[str, NDArray], model: dict[str, NDArray]) -> RigTrace:
    """Run `run` of `system` with `data` and `model` (family -> (n, k)); sigma: the weights the fit uses."""
    rig, cfg = system.rigs[run], system.config
    weights = system.weights[min(run, len(system.weights) - 1)]
    channels = tuple(
        (name, f, data[f][:, k], model[f][:, k], float(weights[f][k]))
        for f in system.families
        for k, name in enumerate(s.name for s in cfg.layout if s.family == f)
    )
    return RigTrace(rig.t, dict(zip(cfg.input_names, rig.u.T, strict=True)), channels)


def plot_trace(tr: RigTrace, path: str | Path, title: str, data_label: str, model_label: str) -> None:
    """The inputs on top, then per channel the data over the model (left) and their difference against ±1 sigma
    (right)."""
    rows = len(tr.channels) + 1
    fig, axes = plt.subplots(rows, 2, figsize=(12, 2.0 * rows + 0.6), sharex=True, squeeze=False,
                             constrained_layout=True)  # fmt: skip
    for name, u in tr.inputs.items():
        ax = axes[0, 1] if name == "force" else axes[0, 0]
        ax.plot(tr.t, u if name == "force" else 1e3 * u, lw=0.8, label=name)
        ax.set_ylabel("force [N]" if name == "force" else "road [mm]")
        ax.legend(fontsize=8, loc="upper right")
    if "force" not in tr.inputs:
        axes[0, 1].axis("off")
    for row, (name, family, data, model, sigma) in zip(axes[1:], tr.channels, strict=True):
        unit, scale = AXES[family]
        row[0].plot(tr.t, scale * data, lw=0.5, color="0.6", label=data_label)
        row[0].plot(tr.t, scale * model, lw=1.0, color="C3", label=model_label)
        row[0].set_ylabel(f"{name} [{unit}]")
        residual = data - model
        row[1].plot(tr.t, scale * residual, lw=0.5, color="C0")
        row[1].axhspan(-scale * sigma, scale * sigma, color="C2", alpha=0.25, lw=0, label="±1 sigma (noise)")
        chi2 = float(np.mean((residual / sigma) ** 2)) if sigma > 0 else float("inf")
        row[1].set_ylabel(f"difference [{unit}]")
        row[1].set_title(f"{name}: chi²/sample {chi2:.3g}", fontsize=9)
    axes[1, 0].legend(fontsize=8, loc="upper right")
    axes[1, 1].legend(fontsize=8, loc="upper right")
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    fig.suptitle(title)
    save(fig, path)


def campaign_figures(cls, campaigns: Sequence, files: Sequence[str], out_dir: Path) -> list[Path]:
    """fitted_<stem>.png per campaign (fitted_<stem>_run<i>.png per run of several): the data (the measured runs,
    or run 0's simulated data) against the rig at the first run's estimate."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for campaign, file in zip(campaigns, files, strict=True):
        runs = campaign.data_files or (() if campaign.data_file is None else (campaign.data_file,))
        system = cls(campaign.config, DataSource(tuple(runs)))
        estimate = np.asarray(campaign.records[0].estimate, dtype=float)
        reference = system.reference(0)
        for r, data in enumerate(reference):
            model = {f: v[0] for f, v in system.outputs(estimate[None, :], r).items()}
            name = f"fitted_{Path(file).stem}" + (f"_run{r + 1}" if len(reference) > 1 else "") + ".png"
            label = system.rigs[r].source if runs else "simulated run 0"
            plot_trace(trace(system, r, data, model), out_dir / name, f"Measured against fitted: {label}",
                       "measured" if runs else "simulated (noisy)", "fitted rig (the estimate)")  # fmt: skip
            written.append(out_dir / name)
    return written
