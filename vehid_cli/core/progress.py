"""Progress where no terminal shows a bar (logs, CI, job schedulers): one plain line per finished step, with the
time elapsed and, when the number of steps is known, an estimate of the time left. `ProgressHook` is how a library
loop reports its steps (no UI code in the library: the command turns the calls into a bar or lines)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

ProgressHook = Callable[[str, int, "int | None"], None]  # (stage, steps done, steps in the stage or None)


@dataclass
class _Task:
    description: str
    total: float | None
    completed: float = 0
    started: float = field(default_factory=lambda: time.monotonic())
    unit: str | None = None  # what a step is (else the progress's own unit)


def eta(elapsed: float, done: float, total: float | None) -> float | None:
    """Seconds left at the pace so far (None: nothing done yet or no total)."""
    if total is None or done <= 0:
        return None
    return max(elapsed / done * (total - done), 0.0)


class PlainProgress:
    """The part of rich.progress.Progress the commands use (add_task, update, advance, a context), printing
    `identify ga/f1: run 7/30 done (12.3 s elapsed)` each time a task completes a step."""

    def __init__(self, verb: str, unit: str, write: Callable[[str], None]):
        self.verb, self.unit, self.write = verb, unit, write
        self.tasks: list[_Task] = []

    def __enter__(self) -> PlainProgress:
        return self

    def __exit__(self, *exc) -> None:
        return None

    def add_task(self, description: str, total: float | None = None, unit: str | None = None, **_) -> int:
        """A new task (`unit`: what its steps are, else the progress's); its id for update and advance."""
        self.tasks.append(_Task(description, total, unit=unit))
        return len(self.tasks) - 1

    def update(
        self,
        task_id: int,
        *,
        completed: float | None = None,
        description: str | None = None,
        total: float | None = None,
        **_,
    ) -> None:
        """Set a task's description, total and/or count of finished steps (a line for each newly finished one)."""
        task = self.tasks[task_id]
        if description is not None:
            task.description = description
        if total is not None:
            task.total = total
        if completed is not None:
            for done in range(int(task.completed) + 1, int(completed) + 1):
                self._line(task, done)
            task.completed = completed

    def advance(self, task_id: int, advance: float = 1) -> None:
        """One (or `advance`) more step of the task finished."""
        self.update(task_id, completed=self.tasks[task_id].completed + advance)

    def _line(self, task: _Task, done: int) -> None:
        of = f"/{int(task.total)}" if task.total is not None else ""
        elapsed = time.monotonic() - task.started
        left = eta(elapsed, done, task.total)
        more = "" if left is None or done >= (task.total or 0) else f", about {left:.0f} s left"
        unit = task.unit or self.unit
        self.write(f"{self.verb} {task.description}: {unit} {done}{of} done ({elapsed:.1f} s elapsed{more})")
