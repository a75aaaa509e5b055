"""Dropped frames: which frames a tracker did not really track, and stand-ins for them.

A caller marks them with ``valid`` (F,) bool; besides, a frame whose points are all NaN
(an exporter's hole) or exactly equal to the frame before (a tracker holding its last
fit: real tracked points never repeat to the last bit) is dropped. A dropped frame would
pin the skull where it was a frame ago, a step and a jerk in the solved motion, so the
solvers see a stand-in instead: every vertex interpolated linearly in world space between
the nearest tracked frames (held at the ends), a smooth rigid-enough bridge over a few
frames that the spline then follows.
"""
from __future__ import annotations

import numpy as np


def tracked_frames(world: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
    """(F,) bool: frames that are valid (if given), not all NaN, and not a repeat of the frame before."""
    frames = len(world)
    tracked = np.ones(frames, dtype=bool) if valid is None else np.asarray(valid, dtype=bool).copy()
    if tracked.shape != (frames,):
        raise ValueError(f"valid must be ({frames},), one flag per frame, got {tracked.shape}")
    for f in range(frames):
        if np.isnan(world[f]).all() or (f > 0 and np.array_equal(world[f], world[f - 1])):
            tracked[f] = False
    if not tracked.any():
        raise ValueError("every frame is dropped (marked invalid, all NaN, or a repeat): nothing to stabilize")
    return tracked


def bridge_dropped(world: np.ndarray, tracked: np.ndarray) -> np.ndarray:
    """world with its untracked frames replaced by interpolation between tracked ones (a copy
    only if some frame is dropped)."""
    if tracked.all():
        return world
    filled = np.array(world, copy=True)
    good = np.flatnonzero(tracked)
    for f in np.flatnonzero(~tracked):
        after = np.searchsorted(good, f)
        before = good[after - 1] if after > 0 else good[0]
        after = good[after] if after < len(good) else good[-1]
        t = 0.0 if after == before else (f - before) / (after - before)
        filled[f] = (1.0 - t) * world[before] + t * world[after]
    return filled
