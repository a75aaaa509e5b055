"""Per-frame rigid alignment: the simple stabilizers and mode pursuit's initializations.

Each frame's world points are aligned on their own to a target (the rest mesh, or a
reference frame) with identity, three-point, weighted Procrustes or robust ICP, in
blocks of frames so that memory stays bounded on long takes. No temporal smoothing:
that is what mode pursuit adds.
"""
from __future__ import annotations

import numpy as np

from facedyn.geometry import rigid

METHODS = ("identity", "three-point", "procrustes", "icp")


def align_frames(
    world: np.ndarray,
    target: np.ndarray,
    method: str,
    weights: np.ndarray | None = None,
    three_point: tuple[int, int, int] | None = None,
    icp_loss: str = "geman-mcclure",
    icp_iterations: int = 10,
    block: int = 1024,
) -> tuple[np.ndarray, np.ndarray]:
    """World-to-target rigid maps (rot (F, 3, 3), trans (F, 3)) with target ~ rot @ world + trans.

    world: (F, N, 3); target: (N, 3); weights: (N,) per-vertex weights or 0/1 mask for
    Procrustes and ICP (None: all vertices); three_point: the vertex indices that
    three-point alignment uses.
    """
    if method not in METHODS:
        raise ValueError(f"alignment method must be one of {METHODS}, got {method!r}")
    world = np.asarray(world)
    target = np.asarray(target, dtype=np.float64)
    if world.ndim != 3 or world.shape[2] != 3:
        raise ValueError(f"world points must be (frames, N, 3), got {world.shape}")
    if target.shape != world.shape[1:]:
        raise ValueError(f"target must be {world.shape[1:]}, got {target.shape}")
    frames = world.shape[0]
    rot = np.broadcast_to(np.eye(3), (frames, 3, 3)).copy()
    trans = np.zeros((frames, 3))
    if method == "identity":
        return rot, trans
    if method == "three-point" and three_point is None:
        raise ValueError("three-point alignment needs three_point=(i, j, k) vertex indices")
    for start in range(0, frames, block):
        chunk = world[start : start + block].astype(np.float64)
        if method == "three-point":
            r, t = rigid.three_point(chunk, target, three_point)
        elif method == "procrustes":
            r, t = rigid.kabsch(chunk, target, weights)
        else:
            r, t, _ = rigid.robust_icp(chunk, target, weights, loss=icp_loss, iterations=icp_iterations)
        rot[start : start + block] = r
        trans[start : start + block] = t
    return rot, trans
