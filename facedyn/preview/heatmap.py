"""Per-vertex heat-map colours of dynamics offsets, shared by images and the usdview layer."""
from __future__ import annotations

import numpy as np

from facedyn.preview.colormap import diverging, normal_component_mm
from facedyn.geometry.mesh import VertexNormals


def symmetric_range_mm(signed_mm: np.ndarray, percentile: float = 99.5, floor_mm: float = 0.5) -> float:
    """A symmetric colour range that saturates only the most extreme offsets, rounded up to 0.5 mm."""
    extreme = float(np.percentile(np.abs(signed_mm), percentile)) if signed_mm.size else 0.0
    return max(floor_mm, np.ceil(extreme * 2.0) / 2.0)


def offset_heat(points: np.ndarray, offsets: np.ndarray, triangles: np.ndarray, range_mm: float | None = None):
    """(colours (F,N,3) in [0,1], signed normal offsets (F,N) in mm, the range used) for cm meshes."""
    points = np.asarray(points, dtype=np.float32)
    offsets = np.asarray(offsets, dtype=np.float32)
    if points.shape != offsets.shape:
        raise ValueError(f"offsets {offsets.shape} do not match points {points.shape}")
    normals = VertexNormals(triangles, points.shape[-2], np.float32)(points)
    signed = normal_component_mm(offsets, normals)
    range_mm = symmetric_range_mm(signed) if range_mm is None else float(range_mm)
    return diverging(signed, range_mm), signed, range_mm
