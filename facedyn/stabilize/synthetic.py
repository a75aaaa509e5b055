"""Synthetic takes with known skull motion, for stabilizer tests and benchmarks.

A face-like surface (the front of an ellipsoid, cm) makes expressions that return to
rest most of the time (jaw, smile, brows: up to ``deform_cm``; a small squint that moves
the eye corners and nose tip too, so three-point alignment is biased as on real faces),
moved by a smooth random rigid motion, plus tracking noise. Every frame's true skull
transform is known, so a stabilizer's error is measurable in cm.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facedyn.geometry import quaternion

AXES = np.array([7.5, 10.0, 9.0])  # head semi-axes, cm (x: ear to ear, y: up, z: forward)


@dataclass
class SyntheticCapture:
    world: np.ndarray  # (F, N, 3) float32 tracked points in world space
    skull: np.ndarray  # (F, N, 3) the same points in true skull space
    rest: np.ndarray  # (N, 3) undeformed surface, skull space
    translate: np.ndarray  # (F, 3) true skull -> world
    orient: np.ndarray  # (F, 4) wxyz
    deforming: np.ndarray  # (N,) bool: vertices that move more than 1 mm in some frame
    three_point: tuple[int, int, int]  # eye corners and nose tip
    fps: float


def _face_surface(vertices: int) -> np.ndarray:
    """(vertices, 3) points spread evenly (Fibonacci) over the front of the head ellipsoid."""
    k = np.arange(vertices) + 0.5
    z = k / vertices  # uniform in (0, 1): a hemisphere of directions facing +z
    phi = np.pi * (3.0 - np.sqrt(5.0)) * k
    r = np.sqrt(1.0 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1) * AXES


def _nearest(points: np.ndarray, direction) -> int:
    d = np.asarray(direction, dtype=np.float64)
    target = d / np.linalg.norm(d) * AXES
    return int(np.argmin(np.linalg.norm(points - target, axis=1)))


def _smooth_curves(rng, t: np.ndarray, count: int, amplitude: float) -> np.ndarray:
    """(len(t), count) sums of a few random sinusoids (0.1-1.5 Hz), peak |value| = amplitude."""
    out = np.zeros((len(t), count))
    for c in range(count):
        for _ in range(4):
            out[:, c] += rng.normal() * np.sin(2 * np.pi * rng.uniform(0.1, 1.5) * t + rng.uniform(0, 2 * np.pi))
    return out * amplitude / max(np.abs(out).max(), 1e-12)


def _activations(rng, t: np.ndarray, count: int, rate: float = 0.4) -> np.ndarray:
    """(len(t), count) expression weights: zero (rest) most of the time, smooth bumps."""
    out = np.zeros((len(t), count))
    duration = t[-1] - t[0] if len(t) > 1 else 1.0
    for c in range(count):
        for _ in range(rng.poisson(rate * duration) + 1):
            start, length = rng.uniform(t[0], t[-1]), rng.uniform(0.3, 1.2)
            phase = np.clip((t - start) / length, 0.0, 1.0)
            out[:, c] = np.maximum(out[:, c], rng.uniform(0.3, 1.0) * np.sin(np.pi * phase) ** 2)
    return out


def synthetic_take(
    frames: int = 651,
    vertices: int = 1185,
    fps: float = 120.0,
    seed: int = 0,
    noise: float = 0.002,
    rotation_deg: float = 10.0,
    translation_cm: float = 2.0,
    deform_cm: float = 1.0,
    world_offset=(0.0, 160.0, 0.0),
) -> SyntheticCapture:
    if frames < 1 or vertices < 10:
        raise ValueError(f"need frames >= 1 and vertices >= 10, got {frames} and {vertices}")
    rng = np.random.default_rng(seed)
    rest = _face_surface(vertices)
    x, y, z = rest.T
    t = np.arange(frames) / fps
    eyes = [_nearest(rest, (-0.35, 0.25, 0.9)), _nearest(rest, (0.35, 0.25, 0.9))]
    nose = _nearest(rest, (0.0, 0.0, 1.0))

    def bump(center, radius):  # smooth (C2) with compact support: the rest of the head stays rigid
        return np.maximum(1.0 - np.sum((rest - center) ** 2, axis=1) / radius**2, 0.0) ** 3

    jaw = np.clip((-2.0 - y) / 5.0, 0.0, 1.0) ** 2
    cheeks = bump(np.array([-3.5, -3.0, 7.5]), 4.0) + bump(np.array([3.5, -3.0, 7.5]), 4.0)
    brows = bump(np.array([0.0, 5.5, 7.0]), 5.0)
    squint = sum(bump(rest[i], 3.0) for i in eyes + [nose])
    fields = [
        np.stack([0 * x, -jaw, -0.3 * jaw], 1),  # jaw open
        np.stack([0.5 * np.sign(x) * cheeks, 0.4 * cheeks, 0 * x], 1),  # smile
        np.stack([0 * x, 0.6 * brows, 0 * x], 1),  # brow raise
        np.stack([0 * x, 0.08 * squint, 0.04 * squint], 1),  # squint: eye corners and nose too
    ]
    act = _activations(rng, t, len(fields))
    offsets = deform_cm * np.einsum("fk,knc->fnc", act, np.stack(fields))
    rotvec = _smooth_curves(rng, t, 3, np.deg2rad(rotation_deg))
    translate = _smooth_curves(rng, t, 3, translation_cm) + np.asarray(world_offset, dtype=np.float64)
    orient = quaternion.from_rotvec(rotvec)
    skull_clean = rest[None] + offsets
    world = np.einsum("fij,fnj->fni", quaternion.to_matrix(orient), skull_clean) + translate[:, None, :]
    world = world + rng.normal(scale=noise, size=world.shape)
    skull = np.einsum("fji,fnj->fni", quaternion.to_matrix(orient), world - translate[:, None, :])
    deforming = np.linalg.norm(offsets, axis=2).max(axis=0) > 0.1
    three = (eyes[0], eyes[1], nose)
    return SyntheticCapture(world.astype(np.float32), skull, rest, translate, orient, deforming, three, fps)
