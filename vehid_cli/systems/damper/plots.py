"""Damper figures (Fleps-Dezasse Figures 9-10): force over time, over displacement and over velocity, the
measurement and one or more identified models overlaid. Written atomically as PNG."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...core.figures import plt, save


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
