"""Resampling onto regular frame grids: expression curves (linear), mesh points (a cubic
spline, chunk by chunk: CubicResampler), and the time grid and interval lookup that skull
trajectory resampling (facedyn.motion.resample) shares.

Captured curves come at the phone's rate (30 or 60 fps, with dropped rows); the simulator
and the takes run at the capture rate (96-128 fps), so curves are resampled onto its grid.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Iterator

import numpy as np

if TYPE_CHECKING:
    from facedyn.io.livelink import ExpressionCurves


def time_grid(start: float, end: float, fps: float) -> np.ndarray:
    """Times start, start + 1/fps, ... up to `end` (inclusive within 1e-9 frames)."""
    if not fps > 0:
        raise ValueError(f"fps must be positive, got {fps}")
    if end < start:
        raise ValueError(f"time span ends ({end}) before it starts ({start})")
    return start + np.arange(int(np.floor((end - start) * fps + 1e-9)) + 1) / fps


def bracket(times: np.ndarray, new_times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For each new time, the samples around it and the weight of the later one.

    `times` must increase; new times outside them clamp to the first or last sample.
    Returns (lo, hi, w) so that a value is ``(1 - w) * v[lo] + w * v[hi]``.
    """
    times = np.asarray(times, dtype=np.float64)
    new_times = np.asarray(new_times, dtype=np.float64)
    last = len(times) - 1
    hi = np.clip(np.searchsorted(times, new_times, side="right"), 1, max(last, 1))
    hi = np.minimum(hi, last)
    lo = np.maximum(hi - 1, 0)
    span = times[hi] - times[lo]
    w = np.clip(np.divide(new_times - times[lo], span, out=np.zeros_like(new_times), where=span > 0), 0.0, 1.0)
    return lo, hi, w


def resample_curves(curves: ExpressionCurves, fps: float, frame_count: int | None = None) -> ExpressionCurves:
    """Every weight linearly interpolated onto a regular grid from the curves' first time.

    The grid covers the curves' span, or exactly `frame_count` frames (to match a skull
    trajectory), holding the first and last values beyond the captured span.
    """
    start = float(curves.times[0])
    if frame_count is None:
        new_times = time_grid(start, float(curves.times[-1]), fps)
    elif frame_count >= 1 and fps > 0:
        new_times = start + np.arange(frame_count) / fps
    else:
        raise ValueError(f"frame_count and fps must be positive, got {frame_count} frames at {fps} fps")
    lo, hi, w = bracket(curves.times, new_times)
    weights = curves.weights[lo] * (1 - w)[:, None] + curves.weights[hi] * w[:, None]
    return replace(curves, times=new_times, weights=weights.astype(curves.weights.dtype), fps=float(fps))


SPLINE_CONTEXT = 64
"""Source samples read on each side of a chunk resampled by CubicResampler. A cubic spline's
value depends on far samples through its second-derivative system, which is diagonally
dominant by 2 (any sample spacing), so their influence at least halves per sample: beyond
64 samples (2**-64) it is below float64 rounding, and the chunk equals the whole spline."""


COLUMN_BLOCK = 256  # spline columns (coordinates) solved at a time


@dataclass(frozen=True)
class SplineWindow:
    """Output frames [start, stop) of the new grid, computed from the source samples [lo, hi)."""

    start: int
    stop: int
    lo: int
    hi: int


class CubicResampler:
    """Values sampled at increasing `seconds`, onto the grid seconds[0] + k / rate, a chunk at a time.

    The interpolant is one cubic spline through every sample (not-a-knot ends; quadratic or
    linear when there are only 3 or 2 samples), so motion that is a cubic polynomial in time
    comes back exactly and samples already on the grid come back unchanged (up to float32
    rounding). A long take is resampled chunk by chunk (`windows`, then `resample` on each
    window's samples), each chunk from a spline through its samples and SPLINE_CONTEXT more
    on each side, which equals the whole take's spline to float64 rounding; a take of one
    window is exactly the whole take's spline. Grid times past the last sample hold it.
    """

    def __init__(self, seconds: np.ndarray, rate: float):
        self.seconds = np.asarray(seconds, dtype=np.float64)
        if self.seconds.ndim != 1 or self.seconds.size == 0 or np.any(np.diff(self.seconds) <= 0):
            raise ValueError("resampling needs increasing sample times")
        self.rate = float(rate)
        self.count = int(np.floor((self.seconds[-1] - self.seconds[0]) * self.rate + 1e-6)) + 1
        self.degree = min(3, self.seconds.size - 1)

    def times(self, start: int, stop: int) -> np.ndarray:
        """The grid times of output frames start..stop-1 (clamped to the last sample)."""
        grid = self.seconds[0] + np.arange(start, stop, dtype=np.float64) / self.rate
        return np.minimum(grid, self.seconds[-1])

    def windows(self, chunk: int) -> Iterator[SplineWindow]:
        """Consecutive chunks of `chunk` output frames, with the source samples each one needs."""
        for start in range(0, self.count, chunk):
            stop = min(start + chunk, self.count)
            times = self.times(start, stop)
            first = int(np.searchsorted(self.seconds, times[0], side="right")) - 1
            last = int(np.searchsorted(self.seconds, times[-1], side="left"))
            lo, hi = max(0, first - SPLINE_CONTEXT), min(self.seconds.size, last + 1 + SPLINE_CONTEXT)
            yield SplineWindow(start, stop, lo, hi)

    def resample(self, window: SplineWindow, values: np.ndarray) -> np.ndarray:
        """float32 values (stop - start, ...) on the window's grid frames, from the (hi - lo, ...) values at its samples.

        The columns (coordinates) go COLUMN_BLOCK at a time: LAPACK's banded solve sweeps
        every column's rows once per row, which stays in cache only for a few hundred columns
        (about 3x faster on 12,000 columns; each column's result is the same), and only a
        block is ever held in float64.
        """
        from scipy.interpolate import make_interp_spline

        values = np.asarray(values)
        if self.seconds.size == 1:
            return values.astype(np.float32)
        seconds, times = self.seconds[window.lo:window.hi], self.times(window.start, window.stop)
        columns = values.reshape(len(values), -1)
        resampled = np.empty((len(times), columns.shape[1]), dtype=np.float32)
        for a in range(0, columns.shape[1], COLUMN_BLOCK):
            block = columns[:, a:a + COLUMN_BLOCK].astype(np.float64)
            resampled[:, a:a + COLUMN_BLOCK] = make_interp_spline(seconds, block, k=self.degree, axis=0)(times)
        return resampled.reshape((len(times),) + values.shape[1:])
