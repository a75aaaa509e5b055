"""Resampling onto regular frame grids: expression curves here, and the time grid and
interval lookup that skull trajectory resampling (facedyn.motion.resample) shares.

Captured curves come at the phone's rate (30 or 60 fps, with dropped rows); the simulator
and the takes run at the capture rate (96-128 fps), so curves are resampled onto its grid.
"""
from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

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
