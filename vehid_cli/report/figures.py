"""The figures of `vehid report --plots`, for any system: the car's campaign figures (`plots.py`) or the
damper's force traces (`damper_plots.py`)."""

from __future__ import annotations

from pathlib import Path

from ..identify.experiment import SimulatedRun
from ..identify.records import Campaign
from ..systems import Simulated
from ..systems.damper.plots import plot_bench, write_damper_plots
from . import system_of
from .plots import plot_responses, write_campaign_plots


def write_plots(campaigns: list[Campaign], files: list[str], out_dir: str | Path) -> list[Path]:
    """All figures for a set of campaign files of one system; returns the paths written."""
    if system_of(campaigns, files) == "damper":
        return write_damper_plots([c.findings for c in campaigns], [Path(f).stem for f in files], out_dir)
    return write_campaign_plots(campaigns, files, out_dir)


def plot_simulation(simulated: Simulated, path: str | Path) -> None:
    """The figure of `vehid simulate --plot`: the car's responses, or the bench run's force."""
    run = simulated.run
    if isinstance(run, SimulatedRun):
        plot_responses(run, path)
    else:
        plot_bench(run.history, run.clean, path, simulated.title)
