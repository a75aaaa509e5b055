"""Skull transforms T(t) on arrays: checking them and moving points between world and skull.

T(t) maps skull space to world space, ``world = R(q) @ skull + t`` (facedyn.performance);
the dynamics papers write T(t)^-1 x for the skin "in the canonical frame", which is
``R^T (x - t)`` here. Everything is batched over frames and done in float64.
"""
from __future__ import annotations

import numpy as np

from facedyn.geometry import quaternion


def check_transforms(translate, orient, frame_count: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(translate (F,3), orient (F,4)) as float64, with shapes checked; None = identity."""
    if translate is None and orient is None and frame_count is None:
        raise ValueError("skull transforms need translate, orient or a frame count")
    if frame_count is None:
        frame_count = len(translate) if translate is not None else len(orient)
    t = np.zeros((frame_count, 3)) if translate is None else np.asarray(translate, dtype=np.float64)
    q = quaternion.identity((frame_count,)) if orient is None else np.asarray(orient, dtype=np.float64)
    if t.shape != (frame_count, 3):
        raise ValueError(f"skull translate must be ({frame_count}, 3), got {t.shape}")
    if q.shape != (frame_count, 4):
        raise ValueError(f"skull orient must be ({frame_count}, 4) quaternions (w, x, y, z), got {q.shape}")
    norms = np.linalg.norm(q, axis=1)
    if not np.all(np.isfinite(t)) or not np.all(np.isfinite(q)) or np.any(norms < 1e-8):
        raise ValueError("skull transforms must be finite with non-zero quaternions")
    return t, q


def check_points(points, name: str = "points") -> np.ndarray:
    p = np.asarray(points)
    if p.ndim != 3 or p.shape[2] != 3:
        raise ValueError(f"{name} must be (frames, points, 3), got {p.shape}")
    if p.shape[0] == 0:
        raise ValueError(f"{name} has no frames")
    return p


def to_skull(world: np.ndarray, translate: np.ndarray, orient: np.ndarray) -> np.ndarray:
    """T(t)^-1 x(t) for (F, N, 3) world points: R(t)^T (x - t(t)), float64."""
    rot = quaternion.to_matrix(orient)
    return np.einsum("fji,fnj->fni", rot, np.asarray(world, dtype=np.float64) - translate[:, None, :])


def to_world(skull: np.ndarray, translate: np.ndarray, orient: np.ndarray) -> np.ndarray:
    """T(t) p(t) for (F, N, 3) skull-space points: R(t) p + t(t), float64."""
    rot = quaternion.to_matrix(orient)
    return np.einsum("fij,fnj->fni", rot, np.asarray(skull, dtype=np.float64)) + translate[:, None, :]


def skull_space(points, translate, orient, space: str) -> np.ndarray:
    """The points in skull space, float64, from either ``space='skull'`` or ``'world'``."""
    p = check_points(points)
    if space == "skull":
        return p.astype(np.float64)
    if space == "world":
        t, q = check_transforms(translate, orient, len(p))
        return to_skull(p, t, q)
    raise ValueError(f"space must be 'skull' or 'world', got {space!r}")
