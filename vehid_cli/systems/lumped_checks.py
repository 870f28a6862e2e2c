"""The measurement chain's checks of a linear rig's measured runs (`vehid check`, and identify's stop on a
failure): every channel beside the configured rig's prediction of it, through the generic checks of
`diagnose.checks` (each registered fault's check, the noise, a trigger offset), one run after another."""

from __future__ import annotations

from ..diagnose.checks import Checks, check_channels
from ..models.faults.base import Channel
from .base import System as LumpedSystem  # a systems.lumped.LumpedSystem (which imports this module)


def channel_views(system: LumpedSystem, run: int) -> tuple[Channel, ...]:
    """Run `run`'s measured channels beside the configured rig's prediction (the configured values of every
    parameter), each with the sigma the fit weights it with."""
    rig = system.rigs[run]
    prediction = system.outputs(system.box.nominal[None, :], run)
    kinds = {s.name: s.kind for s in system.config.layout}
    free = system.config.data.offsets == "identify"
    out = []
    for family in system.families:
        names = [s.name for s in system.config.layout if s.family == family]
        for k, name in enumerate(names):
            y, p = rig.measured[family][:, k], prediction[family][0, :, k]
            out.append(Channel(
                name=name, family=family, column=k, kind=kinds[name], t=rig.t, y=y - y.mean(), pred=p - p.mean(),
                sigma=float(system.weights[run][family][k]), raw=y, pred_mean=float(p.mean()), offsets_free=free,
            ))  # fmt: skip
    return tuple(out)


def rig_checks(system: LumpedSystem) -> Checks:
    """The checks of every measured run of the rig (several: each finding tagged with its run's file)."""
    from_data = system.sigma_source.startswith("estimated")
    found = [check_channels(channel_views(system, r), from_data) for r in range(len(system.rigs))]
    merged = found[0]
    for rig, more in zip(system.rigs[1:], found[1:], strict=True):
        merged = merged.merged(more, system.rigs[0].source, rig.source)
    return merged
