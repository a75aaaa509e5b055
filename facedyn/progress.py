"""Progress for long work: a bar on a terminal, plain lines in batch logs."""
from __future__ import annotations

import sys
import time
from typing import TextIO


class Progress:
    """Report `done / total` of a named task.

    On a terminal it redraws one bar line; otherwise (CI, farm logs) it prints a plain line
    at every 10% so logs stay short and greppable. `Progress.silent()` reports nothing.
    """

    def __init__(self, stream: TextIO | None = None, enabled: bool = True, interactive: bool | None = None):
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = enabled
        self.interactive = self.stream.isatty() if interactive is None else interactive
        self._task = ""
        self._total = 0
        self._done = 0
        self._last_decile = -1
        self._started = time.perf_counter()

    @classmethod
    def silent(cls) -> "Progress":
        return cls(enabled=False)

    def start(self, task: str, total: int) -> None:
        self._task, self._total, self._done, self._last_decile = task, max(int(total), 1), 0, -1
        self._started = time.perf_counter()
        self._draw()

    def advance(self, steps: int = 1) -> None:
        self._done = min(self._done + steps, self._total)
        self._draw()

    def note(self, message: str) -> None:
        """A line of its own (a skipped item, a resumed task) without losing the bar."""
        if not self.enabled:
            return
        self.stream.write(("\r\x1b[K" if self.interactive else "") + message + "\n")
        self.stream.flush()
        if self.interactive:
            self._draw()

    def finish(self) -> None:
        self._done = self._total
        self._draw()
        if self.enabled and self.interactive:
            self.stream.write("\n")
            self.stream.flush()

    def _draw(self) -> None:
        if not self.enabled:
            return
        fraction = self._done / self._total
        elapsed = time.perf_counter() - self._started
        if self.interactive:
            width = 30
            filled = int(round(width * fraction))
            bar = "#" * filled + "-" * (width - filled)
            self.stream.write(f"\r{self._task:<24} [{bar}] {self._done}/{self._total} {elapsed:6.1f}s")
            self.stream.flush()
            return
        decile = int(fraction * 10)
        if decile != self._last_decile:
            self._last_decile = decile
            self.stream.write(f"{self._task}: {self._done}/{self._total} ({fraction:.0%}) {elapsed:.1f}s\n")
            self.stream.flush()
