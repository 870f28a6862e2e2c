"""Progress where no terminal shows a bar (logs, CI, job schedulers): one plain line per finished step."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field


@dataclass
class _Task:
    description: str
    total: float | None
    completed: float = 0
    started: float = field(default_factory=time.monotonic)


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

    def add_task(self, description: str, total: float | None = None, **_) -> int:
        """A new task; its id for update and advance."""
        self.tasks.append(_Task(description, total))
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
        self.write(f"{self.verb} {task.description}: {self.unit} {done}{of} done ({elapsed:.1f} s elapsed)")
