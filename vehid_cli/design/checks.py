"""The `design:` section against the rest of the config (`check_design`: a keyed InputError, exit 2, before any
search), and what the bump's height buys under the configured noise (`noise_note`); the section's own checks are
in `config/design.py`."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..config import Config
from ..config.design import Design
from ..core.errors import InputError
from ..identify.task import build_task
from ..models.sensors import FAMILY
from .plan import apply_plan, configured_plan
from .space import design_space


def check_design(config: Config) -> Design:
    """The design section against the rest of the config; InputError naming the key when it cannot be designed."""
    design = config.design
    src = config.source
    if design is None:
        raise InputError("no 'design' section: give the limits of the test to plan (see docs/design.md)", source=src,
                         key="design")  # fmt: skip
    if config.road.bump is None or config.road.file is not None:
        raise InputError("vehid design plans a bump test: configure road.bump (and no road.file)", source=src,
                         key="road.bump")  # fmt: skip
    name = design.criterion_parameter
    if name is not None and name not in config.identify.unknowns:
        raise InputError(
            f"'{name}' is not an unknown (identify.unknowns: {', '.join(config.identify.unknowns)})", source=src,
            key="design.criterion",
        )  # fmt: skip
    task = build_task(config)
    if task.noise_free:
        raise InputError("noise-free data has a zero bound for every test: set noise.level or noise.sigma",
                         source=src, key="noise.level")  # fmt: skip
    if design.sensors is not None:
        for i, c in enumerate(design.sensors.candidates):
            if FAMILY[c.kind] not in task.families:
                raise InputError(
                    f"a {c.kind} sensor is not used by the objective (families {', '.join(task.families)}; "
                    "see 'sensors' and identify.objective)", source=src, key=f"design.sensors.candidates.{i}.kind",
                )  # fmt: skip
    space = design_space(design)
    if not space.free and design.sensors is None:
        raise InputError("nothing to design: give a range (speed_kmh, heights, shapes, length, duration) or sensors",
                         source=src, key="design")  # fmt: skip
    base = configured_plan(config)
    names = tuple(c.name for c in design.sensors.candidates) if design.sensors else None
    for corner in (space.lower, space.upper):  # the test at the limits must be a valid config
        try:
            apply_plan(config, dataclasses.replace(space.plan(corner, base), sensors=names))
        except InputError as exc:
            raise InputError(f"the test at the limits is not valid: {exc.detail}", source=src,
                             key=f"design ({exc.key})" if exc.key else "design") from None  # fmt: skip
    return design


def noise_note(config: Config) -> str:
    """What the bump's height buys under the configured noise."""
    task = build_task(config)
    floors = [f for f in task.families if np.any(~np.isnan(task.experiment.noise_floors(f)))]
    if not floors:
        return (
            "noise: Eq. 15 (noise.level): sigma scales with each response's spread, so the absolute bump height buys "
            "nothing; the left/right (and front/rear) ratio, speed, shape, length and duration matter"
        )
    return (
        f"noise: absolute floors on {', '.join(floors)} (noise.sigma): a higher bump lowers the bound in proportion, "
        "so the highest corner is at design.heights.max"
    )
