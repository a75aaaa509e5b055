"""Reading a composed take chunk by chunk, so a long take is never whole in memory.

`TakeFrames` opens the take as a processor writing a role sees it (facedyn.usd.take:
the layers below that role; value clips compose as usual), reads the static face setup
once (`head`: a one-frame Performance with the topology, rest, weights, landmarks), and
then reads any range of frames as a Performance of those frames. `windows` walks the take
in chunks with extra frames of context on each side, for steps whose value at a frame
depends on its neighbours (velocities, feature windows, smoothing).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np

from facedyn.performance import Performance
from facedyn.usd.stage import get_prim
from facedyn.usd.take import (find_face_mesh, read_performance, read_skull_transforms, read_stage,
                              select_time_codes, stage_below)


@dataclass(frozen=True)
class Window:
    """Frames [lo, hi) read for the output frames [start, stop) (lo <= start < stop <= hi)."""

    start: int
    stop: int
    lo: int
    hi: int
    take: Performance  # frames lo..hi-1

    @property
    def inner(self) -> slice:
        """The output frames' rows of arrays computed over the window's frames."""
        return slice(self.start - self.lo, self.stop - self.lo)


class TakeFrames:
    """The take below `role_name` at `path`, read a range of frames at a time."""

    def __init__(self, path: str | os.PathLike, role_name: str, frames: tuple[float, float] | None = None,
                 mesh: str | None = None):
        self.stage = stage_below(path, role_name)
        mesh_prim = get_prim(self.stage, mesh) if mesh else find_face_mesh(self.stage)
        self.time_codes = select_time_codes(self.stage, mesh_prim, frames)
        first = float(self.time_codes[0])
        self.head, self.source = read_stage(self.stage, Path(path), mesh, (first, first))
        self._mesh_prim = self.stage.GetPrimAtPath(self.source.mesh_path)
        self._skull_prim = self.stage.GetPrimAtPath(self.source.skull_path) if self.source.skull_path else None

    @property
    def frame_count(self) -> int:
        return len(self.time_codes)

    @property
    def fps(self) -> float:
        return self.head.fps

    def read(self, start: int, stop: int) -> Performance:
        """Frames start..stop-1 (indices into time_codes), checked as read_take checks a whole take."""
        if not 0 <= start < stop <= self.frame_count:
            raise ValueError(f"frames {start}:{stop} outside the take's 0:{self.frame_count}")
        return read_performance(self.stage, self._mesh_prim, self._skull_prim, self.time_codes[start:stop])

    def read_frames(self, indices: np.ndarray) -> Performance:
        """The frames at the given (sorted) indices, e.g. an even sample of a long take."""
        return read_performance(self.stage, self._mesh_prim, self._skull_prim, self.time_codes[np.asarray(indices)])

    def skull(self) -> tuple[np.ndarray, np.ndarray]:
        """The skull's translate (F, 3) and orient (F, 4) over the whole take (small: 7 numbers a frame)."""
        f = self.frame_count
        if self._skull_prim is None:
            return np.zeros((f, 3)), np.tile([1.0, 0.0, 0.0, 0.0], (f, 1))
        return read_skull_transforms(self._skull_prim, self.time_codes)

    def windows(self, chunk: int, margin: int = 0) -> Iterator[Window]:
        """Consecutive chunks of `chunk` output frames, each read with `margin` frames of context per side."""
        for start in range(0, self.frame_count, chunk):
            stop = min(start + chunk, self.frame_count)
            lo, hi = max(0, start - margin), min(self.frame_count, stop + margin)
            yield Window(start, stop, lo, hi, self.read(lo, hi))
