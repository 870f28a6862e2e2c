"""The random streams of a campaign, all from its seed through `SeedSequence.spawn` (never the global NumPy RNG):
the experiment's own stream (a random road), and per run a noise stream and an optimizer stream, the same whatever
the number of runs, of workers or the executor."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class RunStreams:
    """The random generators of one run of a campaign."""

    noise: np.random.Generator
    optimizer: np.random.Generator


def experiment_rng(seed: int) -> np.random.Generator:
    """The experiment's own stream (e.g. a random road): the same for every run of the campaign."""
    experiment_seq, _ = np.random.SeedSequence(seed).spawn(2)
    return np.random.default_rng(experiment_seq)


def run_streams(seed: int, run: int) -> RunStreams:
    """Streams of run `run` (0-based): child `run` of the runs' SeedSequence, split in noise and optimizer."""
    _, runs_seq = np.random.SeedSequence(seed).spawn(2)
    run_seq = runs_seq.spawn(run + 1)[run]
    noise_seq, opt_seq = run_seq.spawn(2)
    return RunStreams(noise=np.random.default_rng(noise_seq), optimizer=np.random.default_rng(opt_seq))
