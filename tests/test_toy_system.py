"""A system is one plug-in: a toy system defined in this module alone (a mass on a spring and a damper, released from
a displacement) registers its config and its System and runs `vehid simulate`, `vehid identify` (a campaign against
its own Cramér–Rao bound) and `vehid report` end to end, with nothing of the package edited."""

from __future__ import annotations

import json
from pathlib import Path
from typing import ClassVar, Literal

import numpy as np
import pytest
import yaml
from numpy.typing import NDArray
from typer.testing import CliRunner

from vehid_cli.cli.app import app
from vehid_cli.config import CONFIGS, register_config
from vehid_cli.config.common import IdentifyCommon, SystemConfig, _Section
from vehid_cli.core.files import write_bytes
from vehid_cli.core.streams import run_streams
from vehid_cli.identify.crlb import CramerRao, cramer_rao_outputs
from vehid_cli.identify.source import DataSource
from vehid_cli.optimizers.base import Problem
from vehid_cli.systems import SYSTEMS, Simulated, System, register_system
from vehid_cli.systems.base import Box


class Oscillator(_Section):
    m: float = 1.0  # [kg]
    k: float = 400.0  # [N/m]
    c: float = 2.0  # [N s/m]
    x0: float = 0.01  # initial displacement [m]
    duration: float = 2.0  # [s]
    dt: float = 0.002  # [s]


class ToyNoise(_Section):
    level: float = 0.05  # Eq. 15 on the displacement


class ToyConfig(SystemConfig):
    system: Literal["toy_oscillator"]
    oscillator: Oscillator = Oscillator()
    noise: ToyNoise = ToyNoise()
    identify: IdentifyCommon


def response(cfg: ToyConfig, k: NDArray, c: NDArray) -> NDArray:
    """x(t) (P, n) of m x'' + c x' + k x = 0 from x0 at rest (underdamped, closed form)."""
    o = cfg.oscillator
    t = np.arange(int(round(o.duration / o.dt))) * o.dt
    k, c = np.asarray(k, dtype=float)[:, None], np.asarray(c, dtype=float)[:, None]
    zeta_w = c / (2 * o.m)
    wd = np.sqrt(np.maximum(k / o.m - zeta_w**2, 1e-12))
    return o.x0 * np.exp(-zeta_w * t) * (np.cos(wd * t) + zeta_w / wd * np.sin(wd * t))


class ToySystem(System):
    """The oscillator as a system: run r fits x(t) with run r's noise by wls."""

    name: ClassVar[str] = "toy_oscillator"
    objective: ClassVar[str] = "wls"

    def __init__(self, config: ToyConfig, source: DataSource | None = None):
        self.config, self.source = config, DataSource.resolve(config, source)
        names = tuple(config.identify.unknowns)
        values = np.array([getattr(config.oscillator, n) for n in names])
        lo, hi = config.identify.bounds
        self.box = Box(names, lo * values, hi * values, values, values.copy())
        self.clean = response(config, *self._kc(values[None, :]))[0]
        self.sigma = {"x": np.array([config.noise.level * np.std(self.clean)])}
        self.sigma_source = f"Eq. 15 with Np = {config.noise.level:g}"

    def _kc(self, X: NDArray) -> tuple[NDArray, NDArray]:
        o = self.config.oscillator
        cols = {n: X[:, j] for j, n in enumerate(self.names)}
        return cols.get("k", np.full(len(X), o.k)), cols.get("c", np.full(len(X), o.c))

    @property
    def residual_samples(self) -> int:
        return int(self.clean.size)

    @classmethod
    def write_simulation(cls, config, target: Path, seed: int, road=None, origin: str = "") -> Simulated:
        system = cls(config)
        x = system.reference(0)
        rows = "".join(f"{i * config.oscillator.dt!r},{v!r}\n" for i, v in enumerate(x))
        write_bytes(target, ("t,x\n" + rows).encode())
        return Simulated(x, f"{x.size} samples")

    def reference(self, run: int) -> NDArray:
        rng = run_streams(self.config.identify.seed, run).noise
        return self.clean + self.sigma["x"][0] * rng.standard_normal(self.clean.size)

    def problem(self, reference: NDArray) -> Problem:
        sigma = self.sigma["x"][0]

        def cost_and_residuals(X: NDArray) -> tuple[NDArray, NDArray]:
            r = (reference[None, :] - response(self.config, *self._kc(X))) / sigma
            return np.mean(r**2, axis=1), r

        return Problem(self.box.lower, self.box.upper, lambda X: cost_and_residuals(X)[0], cost_and_residuals,
                       names=self.names)  # fmt: skip

    def bound(self, at: NDArray | None = None) -> CramerRao:
        at = self.box.truth if at is None else at
        return cramer_rao_outputs(self.names, at, lambda X: response(self.config, *self._kc(X)), self.sigma["x"][0])


@pytest.fixture
def toy(tmp_path):
    register_config("toy_oscillator", ToyConfig)
    register_system(ToySystem)
    path = tmp_path / "toy.yaml"
    path.write_text(yaml.safe_dump({
        "system": "toy_oscillator", "oscillator": {"k": 400.0, "c": 2.0}, "noise": {"level": 0.05},
        "identify": {"unknowns": ["k", "c"], "bounds": [0.5, 2.0], "runs": 6, "seed": 11,
                     "algorithm": {"name": "hybrid", "population": 10, "iterations": 10}},
    }))  # fmt: skip
    yield path
    CONFIGS.pop("toy_oscillator")
    SYSTEMS.pop("toy_oscillator")


def test_a_toy_system_runs_identify_end_to_end(toy, tmp_path):
    runner = CliRunner()
    sim = runner.invoke(app, ["simulate", str(toy), "-o", str(tmp_path / "x.csv")])
    assert sim.exit_code == 0, sim.output
    assert (tmp_path / "x.csv").read_text().startswith("t,x\n")
    out, doc = tmp_path / "toy.h5", tmp_path / "toy.json"
    res = runner.invoke(app, ["identify", str(toy), "--jobs", "1", "-o", str(out), "--json", str(doc)])
    assert res.exit_code == 0, res.output
    result = json.loads(doc.read_text())
    assert result["system"] == "toy_oscillator" and result["objective"] == "wls" and result["runs"] == 6
    sd = {n: result["crlb"]["re_sd_percent"][n] for n in ("k", "c")}
    assert all(0 < v < 50 for v in sd.values())
    for name in ("k", "c"):  # the mean of 6 runs within 4 standard errors of the truth, by the toy's own bound
        assert abs(result["re_percent"][name]) < 4 * sd[name] / np.sqrt(6) + 1e-9, (name, result["re_percent"], sd)
    assert 0.6 < result["nre_over_crlb"] < 1.6
    rep = runner.invoke(app, ["report", str(out)])
    assert rep.exit_code == 0 and "toy_oscillator" in rep.output and "CRLB" in rep.output, rep.output
    md = runner.invoke(app, ["report", str(out), "--format", "md"])
    assert md.exit_code == 0 and "| k |" in md.output.replace(f"| {out} | k |", "| k |")
