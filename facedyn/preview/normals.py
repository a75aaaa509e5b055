"""Area-weighted vertex normals for a fixed triangle list.

Shading and the signed-offset colour map both need vertex normals for every frame of a
sequence whose connectivity never changes, so the vertex/triangle incidence is built once
as a sparse matrix and each frame costs one sparse product.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def face_normals(points: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Unnormalized face normals (cross products, length = twice the area): (..., T, 3)."""
    p = np.asarray(points, dtype=np.float64)
    a, b, c = (p[..., triangles[:, k], :] for k in range(3))
    return np.cross(b - a, c - a)


def normalize(v: np.ndarray) -> np.ndarray:
    """Unit vectors along the last axis; zero vectors stay zero instead of becoming NaN."""
    length = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(length > 0.0, length, 1.0)


class VertexNormals:
    """Computes unit vertex normals (sum of incident face normals, area weighted)."""

    def __init__(self, triangles: np.ndarray, point_count: int):
        tris = np.asarray(triangles)
        if tris.ndim != 2 or tris.shape[1] != 3:
            raise ValueError(f"triangles must be (T, 3), got {tris.shape}")
        if tris.size and (tris.min() < 0 or tris.max() >= point_count):
            raise ValueError(f"triangle indices must lie in [0, {point_count}), got [{tris.min()}, {tris.max()}]")
        self.triangles = tris.astype(np.int64)
        self.point_count = int(point_count)
        t = len(tris)
        rows = self.triangles.ravel()
        cols = np.repeat(np.arange(t), 3)
        self._incidence = sp.csr_matrix((np.ones(3 * t), (rows, cols)), shape=(point_count, t))

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """Unit normals for (N, 3) or (F, N, 3) points, same shape, float32."""
        p = np.asarray(points)
        if p.ndim not in (2, 3) or p.shape[-2:] != (self.point_count, 3):
            raise ValueError(f"points must be ({self.point_count}, 3) or (F, {self.point_count}, 3), got {p.shape}")
        fn = face_normals(p, self.triangles)  # (..., T, 3)
        lead = fn.shape[:-2]
        stacked = np.moveaxis(fn, -2, 0).reshape(len(self.triangles), -1)  # (T, F*3)
        vn = (self._incidence @ stacked).reshape((self.point_count,) + lead + (3,))
        return normalize(np.moveaxis(vn, 0, -2)).astype(np.float32)
