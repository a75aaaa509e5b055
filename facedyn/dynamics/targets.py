"""Quasistatic training targets for held expressions (papers/000 §5.2, eqs. 5-6).

While an expression is held, the skin should move rigidly with the skull; what the skin
does beyond that within a short window (2w+1 = 21 frames, 175 ms at 120 fps) is
secondary dynamics. So the quasistatic skin is a centred moving average in skull space,

    y_i(t) = T(t) * mean_{k=t-w..t+w} T(k)^-1 x_i(k)          (5)

and the dynamic offset, a skull-frame vector, is

    dx_i(t) = T(t)^-1 (x_i(t) - y_i(t)) = T(t)^-1 x_i(t) - mean_k T(k)^-1 x_i(k)   (6)

(T^-1 of a difference of points is the rotation R^T alone). Ends: the window's indices are
clamped to [0, F-1], so near the ends the first or last frame counts several times and the
divisor stays 2w+1; the first and last w frames' targets are therefore biased towards the
end frames, which is why training can leave them out (facedyn.dynamics.training).
"""
from __future__ import annotations

import numpy as np

from facedyn.dynamics.skull import check_points, check_transforms, skull_space, to_world

TARGET_WINDOW = 10


def moving_average(values, window: int = TARGET_WINDOW) -> np.ndarray:
    """Centred mean over frames t-w..t+w of (F, ...) values, indices clamped, float64."""
    v = np.asarray(values, dtype=np.float64)
    if v.ndim < 1 or len(v) == 0:
        raise ValueError(f"values must have a non-empty frame axis, got shape {v.shape}")
    if int(window) != window or window < 0:
        raise ValueError(f"window must be a non-negative whole number of frames, got {window}")
    w = int(window)
    f = len(v)
    if w >= f:  # every window spans the take: its ends' repeats counted, not padded (2w frames of a crafted 10,000-frame window)
        t = np.arange(f, dtype=np.float64).reshape((f,) + (1,) * (v.ndim - 1))
        return ((w - t) * v[0] + v.sum(axis=0) + (t + w - f + 1) * v[-1]) / (2 * w + 1)
    csum = _edge_padded_running_sums(v, w)
    mean = csum[2 * w + 1: 2 * w + 1 + f] - csum[:f]
    mean /= 2 * w + 1
    return mean


def _edge_padded_running_sums(v: np.ndarray, w: int) -> np.ndarray:
    """(F + 2w + 1, ...) float64: 0, then the running sums of v with its first and last frame
    repeated w times before and after, added in the same order as np.cumsum over
    np.pad(v, mode="edge") adds them (the same bits) without building the padded copy: the
    sums are accumulated in place, run by run, each run's first value carrying the sum so far:
    two passes over the take fewer, and no padded copy to allocate (synthesize's expression
    shape on the ICT rig, 1,000 frames x 2,430 vertices, a 21-frame window: 0.075 -> 0.053 s, best of 5)."""
    f = len(v)
    sums = np.empty((f + 2 * w + 1,) + v.shape[1:])
    sums[0] = 0.0
    runs = (np.broadcast_to(v[0], (w,) + v.shape[1:]), v, np.broadcast_to(v[-1], (w,) + v.shape[1:]))
    start = 1
    for run in runs:
        if len(run) == 0:
            continue
        part = sums[start:start + len(run)]
        part[...] = run
        if start > 1:
            part[0] += sums[start - 1]
        np.cumsum(part, axis=0, out=part)
        start += len(run)
    return sums


def dynamic_offsets(points, translate=None, orient=None, *, space: str = "skull", window: int = TARGET_WINDOW) -> np.ndarray:
    """(F, S, 3) dx_i(t) of eq. (6), skull-frame vectors, float64."""
    p = skull_space(points, translate, orient, space)
    return p - moving_average(p, window)


def quasistatic_targets(points, translate, orient, *, space: str = "world", window: int = TARGET_WINDOW) -> np.ndarray:
    """(F, S, 3) y_i(t) of eq. (5) in world space, float64."""
    p = skull_space(points, translate, orient, space)
    t, q = check_transforms(translate, orient, len(check_points(points)))
    return to_world(moving_average(p, window), t, q)
