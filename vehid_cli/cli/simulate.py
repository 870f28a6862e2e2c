"""`vehid simulate`: the configured system on its road (or a measured run's), written as a measurement file."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Optional

import typer

from ..core.errors import InputError
from .common import SetOption, check_writable, guarded, load_config, out


@guarded
def simulate(
    config: Annotated[Path, typer.Argument(metavar="CONFIG", help="Experiment config (YAML).", show_default=False)],
    output: Annotated[
        Path,
        typer.Option(
            "-o",
            "--output",
            metavar="FILE",
            help="Output file: .csv (measurement format), .h5, or .mf4 (a car's run as a data logger records it).",
            show_default=False,
        ),
    ],
    road: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option("--road", metavar="FILE", help="Take road1..road4 and the time grid from this measurement file."),
    ] = None,
    plot: Annotated[
        Optional[Path],  # noqa: UP045
        typer.Option("--plot", metavar="FILE", help="Also draw the responses to this PNG."),
    ] = None,
    seed: Annotated[
        Optional[int],  # noqa: UP045
        typer.Option("--seed", metavar="N", help="Seed of the noise (default identify.seed)."),
    ] = None,
    set_: SetOption = None,
) -> None:
    """Simulate the configured car on its road and write a vehicle measurement file.

    CSV holds the noisy channels of the configured sensors (Eq. 15 or noise.sigma; --set noise.level=0 for clean
    ones); HDF5 holds clean and noisy; MDF4 the noisy channels and the road as a logger records them. The noise
    is the noise stream of run 0 of the campaign with the same seed.
    """
    from ..systems import simulation_suffixes, write_simulation

    target = check_writable(output, simulation_suffixes())
    if plot is not None:
        check_writable(plot, (".png",))
    if seed is not None and not 0 <= seed <= 2**63 - 1:  # as identify.seed: a signed 64-bit integer
        raise InputError(f"--seed must be in [0, {2**63 - 1}], got {seed}")
    cfg = load_config(config, set_ or ())
    seed = cfg.identify.seed if seed is None else seed
    simulated = write_simulation(cfg, target, seed, road, origin=f"simulate {config}")
    if plot is not None:
        from ..report.figures import plot_simulation

        plot_simulation(cfg, simulated, plot)
    out.print(f"wrote {target}: {simulated.summary}" + (f"; figure {plot}" if plot else ""))
