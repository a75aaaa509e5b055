"""Small synthetic faces for the dynamics tests: a curved triangulated sheet with a rigid
top band, a vibrating-platform skull motion, and skin that follows a known linear law."""
from __future__ import annotations

import numpy as np

from facedyn.geometry import quaternion
from facedyn.performance import Topology


def curved_sheet(rows: int, cols: int, width: float = 16.0, height: float = 20.0):
    """(points (rows*cols, 3), Topology) of a sheet bent around Y like a face, facing +Z."""
    ys, xs = np.mgrid[0:rows, 0:cols].astype(np.float64)
    angle = (xs / (cols - 1) - 0.5) * 1.6
    radius = width / 1.6
    x = radius * np.sin(angle)
    z = radius * np.cos(angle) + 0.3 * np.sin(ys / 3.0)
    y = (ys / (rows - 1) - 0.5) * height
    points = np.stack([x.ravel(), y.ravel(), z.ravel()], axis=1)
    a = (np.arange(rows - 1)[:, None] * cols + np.arange(cols - 1)[None, :]).ravel()
    tris = np.concatenate([np.stack([a, a + 1, a + cols + 1], 1), np.stack([a, a + cols + 1, a + cols], 1)])
    topology = Topology(np.full(len(tris), 3, np.int32), tris.astype(np.int32).ravel())
    return points, topology


def top_rows(rows: int, cols: int, count: int) -> np.ndarray:
    """Vertex indices of the top ``count`` rows (the rigid forehead of a sheet)."""
    return np.arange((rows - count) * cols, rows * cols, dtype=np.int32)


def platform_motion(frames: int, fps: float, hz: float, seed: int = 0):
    """(translate, orient): a vibrating platform's up-down bob with a slight nod."""
    time = np.arange(frames) / fps
    phase = np.random.default_rng(seed).uniform(0, 2 * np.pi)
    translate = np.stack([np.zeros(frames), 150.0 + 0.3 * np.sin(2 * np.pi * hz * time + phase), 0.2 * time], axis=1)
    nod = 0.01 * np.sin(2 * np.pi * hz * time + phase + 0.5)
    return translate, quaternion.from_rotvec(np.stack([nod, 0.02 * time, np.zeros(frames)], axis=1))


def jiggle(translate, orient, fps: float, natural_hz: float = 5.0, damping: float = 0.3):
    """(F, 3) skull-frame response y of a damped spring driven by the skull's acceleration:
    y'' + 2 zeta w y' + w^2 y = -R^T t''. A linear law, so the offsets it makes are learnable."""
    dt = 1.0 / fps
    accel = np.gradient(np.gradient(translate, dt, axis=0), dt, axis=0)
    accel = np.einsum("fji,fj->fi", quaternion.to_matrix(orient), accel)
    w = 2 * np.pi * natural_hz
    y, v = np.zeros(3), np.zeros(3)
    out = np.zeros_like(accel)
    for k, a in enumerate(accel):  # semi-implicit Euler, stable at these steps
        v = v + dt * (-a - 2 * damping * w * v - w * w * y)
        y = y + dt * v
        out[k] = y
    return out
