"""Proposals: when the configured test cannot identify every unknown, the cheapest single changes of it that can,
so the user can fix the test they have before adopting the designed one: a road variable (smallest change as a
fraction of the variable's range first) or, with `design.sensors.candidates`, one sensor (add one candidate, or put
a candidate in place of one configured sensor: move or swap). A sensor change counts as SENSOR_CHANGE of a range:
a road variable fixes it more cheaply only within a part of its range; where no road change can (a layout that
cannot see roll), the sensor change is the proposal."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..config import Config, config_from_dict
from ..identify.crlb import bound_from_information
from ..identify.task import build_task
from .criterion import Evaluation
from .scoring import Scorer
from .sensors import channel_information
from .space import Space, line_through, natural

SENSOR_CHANGE = 0.5  # the cost of one sensor mounted, moved or swapped, as a fraction of a road variable's range


@dataclass(frozen=True)
class Proposal:
    """A single-variable change of the configured test that makes every unknown identifiable."""

    variable: str
    value: float  # the new value (natural units: km/h, ratio, m, s; a shape's index into design.shapes)
    text: str  # e.g. "unequal left/right heights: ratio 0.9"
    change: float  # the change as a fraction of the variable's range (the cheapest is the smallest)
    nre_rms_percent: float  # the NRE bound of the changed test
    identifies: tuple[str, ...]  # the unknowns it makes identifiable
    sensors: tuple[str, ...] | None = None  # a sensor change: the layout it gives (names)


def _describe(name: str, value: float, space: Space) -> str:
    if name == "speed_kmh":
        return f"speed {value:.3g} km/h"
    if name == "side":
        return f"unequal left/right heights: ratio {value:.2g}"
    if name == "axle":
        return f"unequal front/rear heights: ratio {value:.2g}"
    if name == "length":
        return f"bump length {value:.3g} m"
    if name == "duration":
        return f"duration {value:.3g} s"
    return f"bump shape {space.shapes[int(value)]}"


def cheapest_changes(
    scorer: Scorer, config: Config, space: Space, configured: Evaluation, points: int
) -> list[Proposal]:
    """Single-variable changes of the configured test (each variable over its grid, the others as configured; the
    heights keep the configured highest corner) that make every unknown identifiable, cheapest (smallest change as
    a fraction of the variable's range) first, one per variable."""
    lost = [n for n, ok in zip(configured.bound.names, configured.bound.identifiable, strict=True) if not ok]
    if not lost:
        return []
    out = sensor_changes(config, configured, tuple(lost))
    if not space.free:
        return sorted(out, key=lambda p: (p.change, p.nre_rms_percent))
    local = dataclasses.replace(space, top=max(configured.plan.heights))
    x0 = local.vector(configured.plan)
    for name in local.free:
        i = local.free.index(name)
        grid, X = line_through(local, x0, name, 2 * points + 1)
        span = max(local.upper[i] - local.lower[i], 1e-300)
        changes = np.abs(grid - x0[i]) / span
        scores = scorer(local, configured.plan, X)
        ok = [k for k, s in enumerate(scores) if np.all(s.identifiable) and changes[k] > 0]
        if not ok:
            continue
        k = min(ok, key=lambda k: (changes[k], scores[k].nre))
        value = float(natural(local, name, grid[k])) if name != "shape" else float(grid[k])
        out.append(Proposal(name, value, _describe(name, value, local), float(changes[k]), scores[k].nre,
                            tuple(lost)))  # fmt: skip
    return sorted(out, key=lambda p: (p.change, p.nre_rms_percent))


def configured_specs(config: Config) -> list[dict]:
    """The configured layout as sensor specs (the paper's corner layout when none is configured)."""
    if config.layout is not None:
        return [s.model_dump(mode="json", exclude_none=True) for s in config.layout]
    return [{"name": f"{f}{i}", "kind": k, "origin": f"corner{i}"}
            for f, k in (("acc", "body_acc"), ("disp", "body_disp")) for i in range(1, 5)]  # fmt: skip


def sensor_changes(config: Config, configured: Evaluation, lost: tuple[str, ...]) -> list[Proposal]:
    """Every single sensor change among `design.sensors.candidates` that makes every unknown identifiable: one
    candidate added, or one configured sensor replaced by a candidate, scored by the channels' Fisher information
    (independent noise: a layout's information is the sum of its channels', from one task with every sensor
    mounted), cheapest (an addition before a replacement, SENSOR_CHANGE each) then lowest NRE bound first; one
    proposal per kind of change (the best addition, the best replacement)."""
    spec = config.design.sensors if config.design is not None else None
    if spec is None:
        return []
    layout = configured_specs(config)
    mounted = [s["name"] for s in layout]
    extra = [c.model_dump(mode="json", exclude_none=True) for c in spec.candidates if c.name not in mounted]
    if not extra:
        return []
    task = build_task(_with_layout(configured.config, layout + extra))  # every sensor mounted, the configured road
    info = channel_information(task)
    at = task.truth if task.truth is not None else task.nominal
    where = {c["name"]: _where(c) for c in extra}
    options = [(mounted + [c], f"add sensor {c} ({where[c]})", 1.0) for c in where]
    options += [([m if m != old else c for m in mounted], f"put sensor {c} ({where[c]}) in place of {old}", 2.0)
                for old in mounted for c in where]  # fmt: skip
    best: dict[float, Proposal] = {}
    for names, text, kind in options:
        if not all(n in info for n in names):
            continue
        bound = bound_from_information(task.names, at, sum(info[n] for n in names))
        if not bound.identifiable.all():
            continue
        p = Proposal("sensors", float("nan"), text, SENSOR_CHANGE * kind, float(bound.nre_rms_percent), lost,
                     tuple(names))  # fmt: skip
        if kind not in best or p.nre_rms_percent < best[kind].nre_rms_percent:
            best[kind] = p
    return [best[k] for k in sorted(best)]


def _with_layout(config: Config, layout: list[dict]) -> Config:
    """The config with this layout (sensor specs)."""
    raw = config.model_dump(mode="json", exclude_none=True, by_alias=True)
    raw["layout"] = layout
    return config_from_dict(raw, source=config.source)


def _where(spec: dict) -> str:
    """Where a sensor spec is mounted, in words."""
    kind = spec["kind"]
    if "corner" in spec and kind in ("wheel_acc", "wheel_disp", "deflection"):
        return f"{kind} at corner {spec['corner']}"
    return f"{kind} at x {spec.get('x', 0.0):g} m, y {spec.get('y', 0.0):g} m from {spec.get('origin', 'cg')}"
