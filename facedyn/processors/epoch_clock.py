"""The clock of F's epochs in `usdfacedyn calibrate`: what its time budget bought, measured.

How fast F trains depends on the machine, its load, torch's threads and the corpus, so no
constant turns minutes into epochs: calibrate gives train-removal minutes
(--budget-minutes), and it stops before an epoch that would end past them. EpochClock
records what each epoch took from the trainer's own progress, for calibration.json.
"""
from __future__ import annotations

import time

from facedyn.progress import Progress


class EpochClock(Progress):
    """A Progress that passes everything to `inner` and notes when each epoch of a training task
    (one whose name starts with `task`) ended, so that a trainer's own progress reports time it."""

    def __init__(self, inner: Progress, task: str = "train F"):
        super().__init__(enabled=False)
        self.inner, self.task = inner, task
        self.started: float | None = None
        self.ends: list[float] = []
        self._timing = False

    def start(self, task: str, total: int) -> None:
        self._timing = task.startswith(self.task)
        if self._timing:
            self.started, self.ends = time.perf_counter(), []
        self.inner.start(task, total)

    def advance(self, steps: int = 1) -> None:
        if self._timing:
            self.ends.extend([time.perf_counter()] * steps)
        self.inner.advance(steps)

    def note(self, message: str) -> None:
        self.inner.note(message)

    def finish(self) -> None:
        self._timing = False
        self.inner.finish()

    def epoch_seconds(self) -> list[float]:
        """Each timed epoch's seconds, the first from the task's start (it includes reading the takes into the feature store)."""
        if self.started is None:
            return []
        marks = [self.started] + self.ends
        return [round(b - a, 3) for a, b in zip(marks, marks[1:])]
