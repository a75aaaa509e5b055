"""F's training budget in `usdfacedyn calibrate`: its epochs from a speed measured on this machine.

How fast F trains depends on the machine, its load, torch's threads and the corpus, so no
constant can turn minutes into epochs. calibrate instead trains F for PROBE_EPOCHS epochs
on PROBE_TAKES of the corpus's takes with the same flags (the probe), times each epoch
(EpochClock), and scales the probe by the corpus's frames: a fixed part (reading the takes,
the feature store, writing) and a part per epoch. F then trains as many epochs as fit the
minutes left for it. The default's epochs therefore depend on the machine's speed;
`--epochs` pins them (and skips the probe).
"""
from __future__ import annotations

import math
import time

from facedyn.progress import Progress

PROBE_TAKES = 12  # corpus takes the probe trains on, spread over the corpus's order
PROBE_EPOCHS = 2  # the last one alone is the probe's epoch time (the first may include warm-up)


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
        """Each timed epoch's seconds, the first from the task's start (it includes building the feature store)."""
        if self.started is None:
            return []
        marks = [self.started] + self.ends
        return [round(b - a, 3) for a, b in zip(marks, marks[1:])]


def probe_takes(names: list[str], count: int = PROBE_TAKES) -> list[str]:
    """`count` of the corpus's take names, evenly spread over its order (all when it has fewer)."""
    if len(names) <= count:
        return list(names)
    return [names[round(i * (len(names) - 1) / (count - 1))] for i in range(count)]


def probe_rates(total_s: float, epoch_s: list[float], frames: int, pairs_per_frame: float) -> dict:
    """What the probe says per corpus frame: the fixed seconds (the probe's whole time less its
    epochs, each as long as its last) and an epoch's seconds, and F's throughput in (frame,
    sample) pairs drawn a second."""
    if len(epoch_s) < 2 or frames < 1:
        raise ValueError(f"a probe needs two timed epochs and some frames, got {len(epoch_s)} epochs of {frames} frames")
    epoch = max(epoch_s[-1], 1e-6)
    fixed = max(total_s - len(epoch_s) * epoch, 0.0)
    return {"frames": int(frames), "seconds": round(total_s, 2), "epoch_seconds": round(epoch, 3),
            "fixed_seconds_per_frame": fixed / frames, "epoch_seconds_per_frame": epoch / frames,
            "pairs_per_second": round(frames * pairs_per_frame / epoch, 1)}


def planned_epochs(train_s: float, probe: dict, frames: int, max_epochs: int) -> dict:
    """As many epochs as fit `train_s` seconds on a corpus of `frames`, by the probe's rates
    (at least one, at most `max_epochs`), and the seconds they should take."""
    fixed = probe["fixed_seconds_per_frame"] * frames
    epoch = probe["epoch_seconds_per_frame"] * frames
    fits = math.floor((train_s - fixed) / epoch) if epoch > 0 else max_epochs
    epochs = int(min(max(fits, 1), max_epochs))
    return {"epochs": epochs, "predicted_fixed_seconds": round(fixed, 1), "predicted_epoch_seconds": round(epoch, 1),
            "predicted_training_seconds": round(fixed + epochs * epoch, 1)}
