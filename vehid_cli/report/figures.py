"""The figures of `vehid report --plots` and `vehid simulate --plot`, for any system: its own (`System.figures`,
`System.plot_simulation`)."""

from __future__ import annotations

from pathlib import Path

from ..identify.records import Campaign
from ..systems import Simulated, system_class
from .campaigns import system_of


def write_plots(campaigns: list[Campaign], files: list[str], out_dir: str | Path) -> list[Path]:
    """All figures for a set of campaign files of one system; returns the paths written."""
    return system_of(campaigns, files).figures(campaigns, files, Path(out_dir))


def plot_simulation(config, simulated: Simulated, path: str | Path) -> None:
    """The figure of `vehid simulate --plot` for the config's system."""
    system_class(config).plot_simulation(simulated, Path(path))
