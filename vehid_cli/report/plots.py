"""Figures (matplotlib, off-screen): written atomically as PNG."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from ..data import atomic_path  # noqa: E402
from ..experiment import SimulatedRun  # noqa: E402


def plot_responses(run: SimulatedRun, path: str | Path) -> None:
    """Road inputs and the body-point displacements and accelerations z1..z4, noisy over clean (Gökdağ Fig. 4)."""
    t = run.experiment.t
    fig, axes = plt.subplots(5, 2, figsize=(11, 11), sharex=True, constrained_layout=True)
    for corner in range(4):
        axes[0, 0].plot(t, 100 * run.experiment.road[:, corner], label=f"road{corner + 1}")
    axes[0, 0].set_ylabel("road [cm]")
    axes[0, 0].legend(ncol=4, fontsize=8)
    axes[0, 1].axis("off")
    axes[0, 1].text(
        0.0, 0.5,
        f"{run.experiment.config.source}\nnoise Np = {100 * run.noise_level:g} % (Eq. 15)\n"
        f"integrator: {run.experiment.config.simulation.integrator}, dt = {1e3 * run.experiment.dt:g} ms",
        va="center", fontsize=10,
    )  # fmt: skip
    for corner in range(4):
        for col, (noisy, clean, unit, scale, name) in enumerate(
            ((run.disp, run.clean.disp, "mm", 1e3, "z"), (run.acc, run.clean.acc, "m/s²", 1.0, "z''"))
        ):
            ax = axes[corner + 1, col]
            if run.noise_level > 0:
                ax.plot(t, scale * noisy[:, corner], lw=0.5, color="0.6", label="measured (noisy)")
            ax.plot(t, scale * clean[:, corner], lw=1.2, color="C0", label="clean")
            ax.set_ylabel(f"{name}{corner + 1} [{unit}]")
            if corner == 0:
                ax.legend(fontsize=8, loc="upper right")
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    fig.suptitle("Body-point responses to the road input")
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)
