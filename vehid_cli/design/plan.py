"""A test as `vehid design` plans it (`Plan`), the height ratios that describe its bump, and the plan written into a
config: what a candidate test is, independently of how it is scored or searched for."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..config import Config, config_from_dict
from ..core.result import Result


@dataclass(frozen=True)
class Plan(Result):
    """One test: speed [km/h], bump heights under corners 1..4 [m], shape, length [m], record duration [s], and
    the mounted sensors (names among design.sensors.candidates; None: the configured layout)."""

    speed_kmh: float
    heights: tuple[float, float, float, float]
    shape: str
    length: float
    duration: float
    sensors: tuple[str, ...] | None = None

    @property
    def side_ratio(self) -> float:
        """Height of side b2 over side b1 (front axle; corners 2 / 1)."""
        return self.heights[1] / self.heights[0] if self.heights[0] > 0 else math.inf

    def to_json(self) -> dict:
        return {
            "speed_kmh": self.speed_kmh, "heights": list(self.heights), "height_ratio_b2_b1": self.side_ratio,
            "shape": self.shape, "length": self.length, "duration": self.duration,
            "sensors": None if self.sensors is None else list(self.sensors),
        }  # fmt: skip


def configured_plan(config: Config) -> Plan:
    """The configured test as a plan."""
    bump = config.road.bump
    return Plan(
        speed_kmh=config.road.V * 3.6, heights=tuple(float(h) for h in bump.heights), shape=bump.shape,
        length=bump.length, duration=config.simulation.duration,
    )  # fmt: skip


def side_of(heights: Sequence[float]) -> float:
    """The side variable s of corner heights (front axle: corner 1 on side b1, corner 2 on side b2)."""
    h1, h2 = heights[0], heights[1]
    top = max(h1, h2)
    if top <= 0:
        return 0.0
    return 1.0 - h2 / h1 if h1 >= h2 else -(1.0 - h1 / h2)


def axle_of(heights: Sequence[float]) -> float:
    """The axle variable a of corner heights (side b1: corner 1 front, corner 4 rear)."""
    front, rear = heights[0], heights[3]
    if max(front, rear) <= 0:
        return 0.0
    return 1.0 - rear / front if front >= rear else -(1.0 - front / rear)


def corner_heights(top: float, side: float, axle: float, low: float = 0.0) -> tuple[float, float, float, float]:
    """Heights [m] of corners 1..4 with the highest at `top`, the side and axle ratios of s and a, none below `low`."""
    b1, b2 = (1.0, 1.0 - side) if side >= 0 else (1.0 + side, 1.0)
    front, rear = (1.0, 1.0 - axle) if axle >= 0 else (1.0 + axle, 1.0)
    h = top * np.array([b1 * front, b2 * front, b2 * rear, b1 * rear])
    return tuple(float(v) for v in np.maximum(h, low))


def apply_plan(config: Config, plan: Plan) -> Config:
    """The config with the plan's road, duration and sensors written in (validated; the source kept)."""
    raw = config.model_dump(mode="json", exclude_none=True, by_alias=True)
    road = raw["road"]
    road.pop("speed", None)
    road["speed_kmh"] = plan.speed_kmh
    road["bump"].update(shape=plan.shape, length=plan.length, heights=list(plan.heights))
    raw["simulation"]["duration"] = plan.duration
    if plan.sensors is not None:
        specs = {c.name: c for c in config.design.sensors.candidates}
        raw["layout"] = [specs[n].model_dump(mode="json", exclude_none=True) for n in plan.sensors]
    return config_from_dict(raw, source=config.source)
