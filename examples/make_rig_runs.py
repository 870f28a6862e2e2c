"""Make four-post rig runs as a data logger records them, from vehid's own simulator (README "Your own test data").

Each run is the configured car on its own random road (the config's road with a different seed), every sensor of
the layout with its noise (noise.sigma), written through `vehid_cli.io.write.write_record` under the logger's
channel names and units of the config's `data:` section. What a real logger adds is added too: the deflection
potentiometers are sampled at 200 Hz (everything else at the simulation's 1 kHz), every accelerometer reads
gravity (+1 g at rest) and a bias of its own, every potentiometer its own zero. Run 1 is MDF4, run 2 MAT v5,
and so on alternately (`--format` fixes one).

    python examples/make_rig_runs.py configs/examples/four_post_rig.yaml -o runs/rig [--runs 2] [--seed 1]
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from vehid_cli.config import load_config
from vehid_cli.core.streams import run_streams
from vehid_cli.identify.experiment import build_experiment, simulate_measurement
from vehid_cli.io.write import write_record
from vehid_cli.models.sensors import FAMILY

G = 9.80665  # m/s² per g: what a DC accelerometer reads at rest
SLOW = {"deflection": 200.0}  # sensor kind -> its sampling rate [Hz] (others at the simulation's rate)
BIAS = {"acc": 0.02 * G, "disp": 0.005}  # standard deviation of a sensor's offset from its nominal zero [m/s², m]


def write_rig_run(
    config: str | Path,
    path: str | Path,
    seed: int,
    overrides: Sequence[str] = (),
    noise_seed: int | None = None,
    flip: Sequence[str] = (),
) -> Path:
    """One run of the config (with `--set`-style `overrides`) on the road of `seed`, with the noise (and sensor
    offsets) of `noise_seed` (default `seed`), written to `path` (.mf4, .mat, .h5, .csv); the sensors named in
    `flip` are mounted upside down (their channels, gravity included, recorded negated)."""
    cfg = load_config(config, [*overrides, f"identify.seed={seed}"])
    noise_seed = seed if noise_seed is None else noise_seed
    experiment = build_experiment(cfg)
    run = simulate_measurement(experiment, run_streams(noise_seed, 0).noise)
    rng = np.random.default_rng(np.random.SeedSequence(noise_seed).spawn(3)[2])  # offsets: a stream of their own
    t, dt = experiment.t, experiment.dt
    channels = {f"road{i + 1}": (t, experiment.road[:, i]) for i in range(4)}
    for sensor in experiment.layout.sensors:
        family = FAMILY[sensor.kind]
        y = run.channels[family][:, experiment.layout.names(family).index(sensor.name)]
        y = y + BIAS[family] * rng.standard_normal() + (G if family == "acc" else 0.0)
        y = -y if sensor.name in flip else y
        step = int(round(1.0 / (SLOW.get(sensor.kind, 1.0 / dt) * dt)))
        channels[sensor.name] = (t[::step], y[::step])
    names = {ours: cfg.data.channels.get(ours, ours) for ours in channels}
    units = {ours: cfg.data.units[ours] for ours in channels if ours in cfg.data.units}
    comment = f"four-post rig run simulated by vehid from {cfg.source}, seed {seed}"
    return write_record(path, channels, units=units, names=names, comment=comment)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("config", type=Path)
    parser.add_argument("-o", "--output", type=Path, required=True, help="directory for the runs")
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument("--seed", type=int, default=1, help="run k uses seed + k - 1 (its road and its noise)")
    parser.add_argument("--format", choices=("mf4", "mat", "h5", "csv"), default=None)
    parser.add_argument("--set", dest="overrides", action="append", default=[], help="dotted.key=value (repeatable)")
    parser.add_argument("--flip", action="append", default=[], help="a sensor mounted upside down (repeatable)")
    args = parser.parse_args()
    args.output.mkdir(parents=True, exist_ok=True)
    for k in range(args.runs):
        fmt = args.format or ("mf4", "mat")[k % 2]
        path = write_rig_run(
            args.config, args.output / f"rig_run{k + 1}.{fmt}", args.seed + k, args.overrides, flip=args.flip
        )
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
