"""Dropped frames: which frames a tracker did not really track, and stand-ins for them.

A caller marks them with ``valid`` (F,) bool; besides, a frame whose points are all NaN
(an exporter's hole) or exactly equal to the frame before (a tracker holding its last
fit: real tracked points never repeat to the last bit) is dropped. A dropped frame would
pin the skull where it was a frame ago, a step and a jerk in the solved motion, so the
solvers see a stand-in instead: every vertex interpolated in world space through the two
nearest tracked frames on each side (a cubic, so the bridge keeps the head's acceleration;
linear with fewer neighbours, held at the ends), which the spline then follows.
"""
from __future__ import annotations

import numpy as np


def tracked_frames(world: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
    """(F,) bool: frames that are valid (if given), not all NaN, and not a repeat of the frame before.

    A capture whose every frame repeats the first is still, not dropped: its frames are all
    tracked (a solve of it gives a still skull), where otherwise one tracked frame would
    leave the smoother nothing to fit.
    """
    frames = len(world)
    tracked = np.ones(frames, dtype=bool) if valid is None else np.asarray(valid, dtype=bool).copy()
    if tracked.shape != (frames,):
        raise ValueError(f"valid must be ({frames},), one flag per frame, got {tracked.shape}")
    given = tracked.copy()
    repeats = np.zeros(frames, dtype=bool)
    for f in range(frames):
        repeats[f] = f > 0 and np.array_equal(world[f], world[f - 1])
        if np.isnan(world[f]).all() or repeats[f]:
            tracked[f] = False
    if frames > 1 and repeats[1:].all() and not np.isnan(world[0]).all():
        return given  # every frame is the first: a still capture (nothing moved), not a tracker holding one fit
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
        neighbours = np.concatenate([good[max(after - 2, 0) : after], good[after : after + 2]])
        if after in (0, len(good)):  # before the first or after the last tracked frame: hold it
            neighbours = good[[min(after, len(good) - 1)]]
        elif after == 1 or after == len(good) - 1:  # one side has a single neighbour: linear
            neighbours = good[after - 1 : after + 1]
        filled[f] = np.einsum("k,k...->...", _lagrange_weights(neighbours, f), world[neighbours].astype(np.float64))
    return filled


def _lagrange_weights(nodes: np.ndarray, x: float) -> np.ndarray:
    """Weights of the values at ``nodes`` that give the interpolating polynomial at x."""
    nodes = nodes.astype(np.float64)
    weights = np.ones(len(nodes))
    for j, node in enumerate(nodes):
        others = np.delete(nodes, j)
        weights[j] = np.prod((x - others) / (node - others))
    return weights
