"""Vertex velocities by the 7-point central difference (O(h^6)), ends included.

Interior frames use (-1, 9, -45, 0, 45, -9, 1) / 60h. The first and last three frames
have no three neighbours on one side, so they use the 7-point one-sided-shifted
stencil of the same order (weights from the Vandermonde system of their offsets) rather
than dropping or clamping frames; takes shorter than 7 frames use every frame they have.
The operator is a sparse (frames x frames) matrix so that its transpose gives the
gradient.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

POINTS = 7


def stencil_weights(offsets: np.ndarray) -> np.ndarray:
    """Weights c with sum_k c_k f(x + o_k h) = h f'(x) + O(h^len(offsets)) (exact for polynomials)."""
    offsets = np.asarray(offsets, dtype=np.float64)
    m = len(offsets)
    vander = np.vander(offsets, m, increasing=True).T  # row j: offsets**j
    rhs = np.zeros(m)
    rhs[1] = 1.0
    return np.linalg.solve(vander, rhs)


def derivative_operator(frames: int, fps: float, dtype=np.float64) -> sp.csr_matrix:
    """Sparse D with (D @ x)[f] = dx/dt at frame f, for x sampled at ``fps`` along axis 0."""
    if frames < 1:
        raise ValueError(f"need at least one frame, got {frames}")
    if not fps > 0:
        raise ValueError(f"fps must be positive, got {fps}")
    if frames == 1:
        return sp.csr_matrix((1, 1), dtype=dtype)
    width = min(POINTS, frames)
    half = (width - 1) // 2
    f = np.arange(frames)
    start = np.clip(f - half, 0, frames - width)
    table = np.stack([stencil_weights(np.arange(width) - k) for k in range(width)]) * fps
    vals = table[f - start]
    cols = start[:, None] + np.arange(width)[None, :]
    rows = np.repeat(f, width)
    vals[np.abs(vals) < 1e-9 * fps] = 0.0  # the central weight: exactly zero, keep it out of the matrix
    matrix = sp.csr_matrix((vals.ravel(), (rows, cols.ravel())), shape=(frames, frames))
    matrix.eliminate_zeros()
    return matrix.astype(dtype)
