"""Damper figures (Fleps-Dezasse Figures 9-10): force over time, over displacement and over velocity, the
measurement and one or more identified models overlaid. Written atomically as PNG."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...core.figures import plt, save
from ...diagnose.residuals import residual_spectrum


def _panels(title: str):
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2), constrained_layout=True)
    axes[0].set_xlabel("t [s]")
    axes[1].set_xlabel("displacement [mm]")
    axes[2].set_xlabel("velocity [mm/s]")
    for ax in axes:
        ax.set_ylabel("force [N]")
        ax.grid(alpha=0.3)
    fig.suptitle(title)
    return fig, axes


def _draw(axes, t, x, v, force, **style) -> None:
    axes[0].plot(t, force, **style)
    axes[1].plot(1e3 * x, force, **style)
    axes[2].plot(1e3 * v, force, **style)


def plot_bench(history, clean, path: str | Path, title: str = "simulated bench run") -> None:
    """A simulated bench run: noisy force (grey) over the clean one."""
    fig, axes = _panels(title)
    if history.force is not None and not np.array_equal(history.force, clean):
        _draw(axes, history.t, history.x, history.v, history.force, lw=0.5, color="0.6", label="noisy")
    _draw(axes, history.t, history.x, history.v, clean, lw=1.2, color="C0", label="clean")
    axes[0].legend(fontsize=8)
    save(fig, path)


def plot_traces(name: str, entries: list[tuple[str, object]], path: str | Path) -> None:
    """One bench run: the measured force (black) and each labelled model's force on it, J in the legend."""
    first = entries[0][1]
    kind, _, run = name.partition(":")
    fig, axes = _panels(f"{run or name} ({'training' if kind == 'train' else 'held out'})")
    _draw(axes, first.t, first.x, first.v, first.measured, lw=1.6, color="k", label="measured")
    for k, (lab, tr) in enumerate(entries):
        _draw(axes, tr.t, tr.x, tr.v, tr.model, lw=1.0, color=f"C{k}", label=f"{lab} (J = {tr.J:.4f})")
    axes[0].legend(fontsize=8, loc="best")
    save(fig, path)


def write_damper_plots(results, labels: list[str], out_dir: str | Path) -> list[Path]:
    """One figure per bench run (training and held-out), every result (a damper campaign's findings) that has a
    trace on it overlaid."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    runs: dict[str, list[tuple[str, object]]] = {}
    for res, lab in zip(results, labels, strict=True):
        for tr in res.traces:
            runs.setdefault(tr.name, []).append((lab, tr))
    written = []
    for name, entries in runs.items():
        safe = name.replace(":", "-").replace("/", "_").replace(" ", "_")
        path = out_dir / f"force-{safe}.png"
        plot_traces(name, entries, path)
        written.append(path)
    return written


def plot_fitted_force(trace, sigma: float, path: str | Path, label: str = "") -> None:
    """One bench run measured against the identified model: the forces over time, the residual with the noise's
    ±1 sigma band, and the residual's amplitude spectral density against the white-noise floor of sigma [N]."""
    fig, axes = plt.subplots(
        1, 3, figsize=(15, 3.8), constrained_layout=True, gridspec_kw={"width_ratios": [2, 2, 1.3]}
    )
    residual = np.asarray(trace.measured) - np.asarray(trace.model)
    fs = 1.0 / float(np.median(np.diff(trace.t)))
    axes[0].plot(trace.t, trace.measured, lw=0.8, color="0.55", label="measured")
    axes[0].plot(trace.t, trace.model, lw=1.0, color="C3", label=f"fitted model (J = {trace.J:.4f})")
    axes[0].set_ylabel("force [N]")
    axes[1].plot(trace.t, residual, lw=0.6, color="C0")
    axes[2].loglog(*_positive(residual_spectrum(residual, fs)), lw=0.8, color="C0", label="residual")
    if np.isfinite(sigma) and sigma > 0:
        axes[1].axhspan(-sigma, sigma, color="C2", alpha=0.2, lw=0, label="±1 sigma (noise)")
        axes[2].axhline(np.sqrt(2.0 * sigma**2 / fs), color="C2", ls="--", lw=1, label="noise floor")
        axes[1].legend(fontsize=8, loc="upper right")
    axes[1].set_ylabel("residual [N]")
    axes[2].set_ylabel("ASD [N/√Hz]")
    axes[0].set_xlabel("t [s]")
    axes[1].set_xlabel("t [s]")
    axes[2].set_xlabel("frequency [Hz]")
    axes[0].legend(fontsize=8, loc="upper right")
    axes[2].legend(fontsize=8, loc="upper right")
    kind, _, run = trace.name.partition(":")
    fig.suptitle(f"Measured against fitted{': ' + label if label else ''}, {run or trace.name} "
                 f"({'training' if kind == 'train' else 'held out'})")  # fmt: skip
    save(fig, path)


def _positive(spectrum):
    """(freq, asd) without the zero frequency (a log axis)."""
    freq, asd = spectrum
    return freq[1:], asd[1:]


def write_fitted_force_plots(campaigns, labels: list[str], out_dir: str | Path) -> list[Path]:
    """fitted-<label>-<run>.png: each campaign's bench runs measured against its identified model."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []
    for c, lab in zip(campaigns, labels, strict=True):
        sigma = np.asarray(c.sigma.get("force", [np.nan]), dtype=float).ravel()
        for tr in c.findings.traces if c.findings is not None else ():
            safe = tr.name.replace(":", "-").replace("/", "_").replace(" ", "_")
            path = out_dir / f"fitted-{lab}-{safe}.png"
            plot_fitted_force(tr, float(sigma[0]) if sigma.size else float("nan"), path, lab)
            written.append(path)
    return written
