"""The screening window of a long record: the first SCREEN_SAMPLES samples of each run, on which a long record's
global search and candidate screening run, while every fit that is kept (the polish of the declared model, the
re-fit of an accepted candidate, its removal test, the intervals and the final model) runs on the whole record.

Why this is sound: the car starts at rest on the first road sample and every integrator steps forward in time, so
the model's response on the window is the first SCREEN_SAMPLES samples of its response on the whole record, bit for
bit; a fit or a likelihood-ratio test on the window is the same fit or test on fewer data (less power, never a
different model). The held-out blocks of the window are the whole record's first ones (block_size is the same for
both once a run has 8 x BLOCK samples), so the window's validation J is on data no window fit has seen. What the
window decides is only where to look: which start the whole record's polish begins from, which candidate is
re-fitted on the whole record; that re-fit, the strength interval, the removal test and the validation J of the
claim are the whole record's.

Cost: a 60 s record at 1 kHz is 12 times the window, and the screening (about 1000 evaluations for the declared
model's global search, 500-1500 per round of candidates) dominates a diagnosis; on the window it costs what a 5 s
record costs. Records up to LONG_RECORD samples per run (every test case, every 3-4 s bump) are not windowed.
"""

from __future__ import annotations

import dataclasses

from ..identify.experiment import Experiment
from ..identify.task import JointTask, Task

SCREEN_SAMPLES = 5000  # samples of each run the screening uses (5 s at 1 kHz)
LONG_RECORD = 2 * SCREEN_SAMPLES  # a run longer than this (samples) is screened on its window
WINDOW_CHUNK_BYTES = 8 * 2**20  # the window's cars simulated at once, at most (their full responses; 4 cars of 5000
# samples): the candidates' fits run two at a time in threads, each whole batch of a forward-difference Jacobian (13
# cars, 23 MB) beside the other's put the 60 s diagnosis's round of candidates 50-60 MiB above its floor (issue 26)


def _head(arrays: dict | None, n: int) -> dict | None:
    """Each (n_total, ...) array of a family -> array mapping cut to its first n rows."""
    return None if arrays is None else {k: v[:n] for k, v in arrays.items()}


def window_task(task: Task | JointTask, n: int = SCREEN_SAMPLES) -> Task | JointTask:
    """The same task on the first `n` samples of each run: the experiment's time grid and road, the measured or
    clean channels, their observed masks and raw values cut to them; the noise sigma, the unknowns and their box
    unchanged. A task whose measurement-chain corrections carry the record's own samples is not cut (ValueError)."""
    if isinstance(task, JointTask):
        return JointTask(tuple(window_task(t, n) for t in task.tasks))
    if task.corrections:
        raise ValueError("a task with measurement-chain corrections among its unknowns has no screening window")
    exp = task.experiment
    head = Experiment(exp.config, exp.t[:n], exp.road[:n], exp.road_source, chunk_bytes=WINDOW_CHUNK_BYTES)
    return dataclasses.replace(
        task, experiment=head, clean=_head(task.clean, n), measured=_head(task.measured, n),
        observed=_head(task.observed, n), raw=_head(task.raw, n),
    )  # fmt: skip


def is_long(task: Task | JointTask) -> bool:
    """Is any run longer than LONG_RECORD samples (and can it be windowed: no measurement-chain corrections)?"""
    runs = task.tasks if isinstance(task, JointTask) else (task,)
    return any(t.experiment.t.size > LONG_RECORD for t in runs) and not any(t.corrections for t in runs)
