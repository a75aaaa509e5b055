"""What a face tracker adds to the true skin: noise, pops and dropped frames, all seeded.

A tracker's error is not only i.i.d. jitter. Optical flow and model fitting drift slowly
(an error that persists for a fraction of a second), neighbouring vertices are fitted
together (an error that is smooth over the surface), a few vertices sometimes jump for a
single frame (a pop: a mismatched feature), and frames get dropped (repeated, or missing).
`add_tracker_noise` puts these on a sequence of points, for tests and benchmarks of the
stabilizer and of the dynamics networks alike. Arrays only (cm, any rigid frame: every
component is isotropic).

Components (standard deviations are per coordinate):
- ``iid_cm``: independent per vertex, frame and coordinate;
- ``temporal_cm``: independent per vertex, smooth in time (Gaussian correlation of
  ``correlation_s`` seconds);
- ``spatial_cm``: smooth over the surface (Gaussian bumps of ``radius_cm`` around random
  vertices, normalized to unit variance per vertex) and smooth in time like the above;
- pops: ``pop_rate`` events per second, each moving the ``pop_vertices`` vertices nearest a
  random vertex by ``pop_cm`` in a random direction for one frame;
- dropped frames: a fraction ``drop_rate`` of frames (never the first), repeated from the
  frame before (``drop_mode="repeat"``, as trackers that hold the last fit) or all NaN
  (``"nan"``, as exporters that leave a hole).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import gaussian_filter1d

DROP_MODES = ("repeat", "nan")
SPATIAL_BUMPS = 256  # bump centres of the spatially smooth part (fewer on small meshes)


@dataclass(frozen=True)
class TrackerNoise:
    iid_cm: float = 0.0
    temporal_cm: float = 0.0
    spatial_cm: float = 0.0
    correlation_s: float = 0.25
    radius_cm: float = 3.0
    pop_rate: float = 0.0  # pops per second
    pop_vertices: int = 12
    pop_cm: float = 0.3
    drop_rate: float = 0.0  # fraction of frames
    drop_mode: str = "repeat"

    def __post_init__(self) -> None:
        for name in ("iid_cm", "temporal_cm", "spatial_cm", "pop_rate", "pop_cm", "drop_rate"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise ValueError(f"tracker noise {name} must be a finite number >= 0, got {value}")
        if not (self.correlation_s > 0 and self.radius_cm > 0):
            raise ValueError("tracker noise correlation_s and radius_cm must be positive")
        if self.drop_rate >= 0.5:
            raise ValueError(f"tracker noise drop_rate must be below 0.5, got {self.drop_rate}")
        if self.pop_vertices < 1:
            raise ValueError(f"tracker noise pop_vertices must be >= 1, got {self.pop_vertices}")
        if self.drop_mode not in DROP_MODES:
            raise ValueError(f"tracker noise drop_mode must be one of {DROP_MODES}, got {self.drop_mode!r}")


@dataclass
class NoisyCapture:
    points: np.ndarray  # (F, N, 3) float32: the tracked points
    valid: np.ndarray  # (F,) bool: False where the frame was dropped
    popped: np.ndarray  # (F, N) bool: vertices a pop moved in that frame


def add_tracker_noise(points: np.ndarray, fps: float, noise: TrackerNoise, surface: np.ndarray, seed: int = 0) -> NoisyCapture:
    """points (F, N, 3) plus the tracker's errors; surface (N, 3): the mesh's rest positions,
    which say what is near what (for the spatially smooth part and for pops)."""
    points = np.asarray(points)
    surface = np.asarray(surface, dtype=np.float64)
    if points.ndim != 3 or points.shape[2] != 3 or len(points) < 1:
        raise ValueError(f"points must be (frames, N, 3), got {points.shape}")
    frames, n, _ = points.shape
    if surface.shape != (n, 3):
        raise ValueError(f"surface must be ({n}, 3) like one frame of points, got {surface.shape}")
    if not fps > 0:
        raise ValueError(f"fps must be positive, got {fps}")
    rng = np.random.default_rng(seed)
    sigma_frames = noise.correlation_s * fps
    out = points.astype(np.float32, copy=True)
    if noise.iid_cm > 0:
        out += rng.normal(0.0, noise.iid_cm, out.shape).astype(np.float32)
    if noise.temporal_cm > 0:
        out += noise.temporal_cm * _smooth_in_time(rng, out.shape, sigma_frames).astype(np.float32)
    if noise.spatial_cm > 0:
        basis = _bump_basis(surface, noise.radius_cm, rng)
        coefficients = _smooth_in_time(rng, (frames, basis.shape[1], 3), sigma_frames)
        out += noise.spatial_cm * np.einsum("nk,fkc->fnc", basis, coefficients).astype(np.float32)
    popped = _add_pops(out, fps, noise, surface, rng)
    valid = _drop_frames(out, noise, rng)
    return NoisyCapture(out, valid, popped)


def _smooth_in_time(rng, shape: tuple[int, ...], sigma_frames: float) -> np.ndarray:
    """Gaussian-filtered white noise along axis 0 with unit variance at every frame (drawn
    with 4 sigma of margin on both sides, so the ends are as random as the middle)."""
    if sigma_frames < 0.5:
        return rng.normal(size=shape)
    margin = int(np.ceil(4 * sigma_frames))
    white = rng.normal(size=(shape[0] + 2 * margin,) + tuple(shape[1:]))
    smooth = gaussian_filter1d(white, sigma_frames, axis=0, mode="constant", truncate=4.0)[margin:-margin]
    kernel = np.exp(-0.5 * (np.arange(-margin, margin + 1) / sigma_frames) ** 2)
    return smooth / np.sqrt(np.sum((kernel / kernel.sum()) ** 2))


def _bump_basis(surface: np.ndarray, radius: float, rng) -> np.ndarray:
    """(N, K) Gaussian bumps around random vertices; each row scaled to unit sum of squares."""
    centres = surface[rng.choice(len(surface), size=min(SPATIAL_BUMPS, len(surface)), replace=False)]
    d2 = np.sum((surface[:, None, :] - centres[None, :, :]) ** 2, axis=-1)
    basis = np.exp(-0.5 * d2 / radius**2)
    return basis / np.sqrt(np.maximum(np.sum(basis**2, axis=1, keepdims=True), 1e-300))


def _add_pops(points: np.ndarray, fps: float, noise: TrackerNoise, surface: np.ndarray, rng) -> np.ndarray:
    frames, n, _ = points.shape
    popped = np.zeros((frames, n), dtype=bool)
    count = rng.poisson(noise.pop_rate * frames / fps) if noise.pop_rate > 0 and noise.pop_cm > 0 else 0
    size = min(noise.pop_vertices, n)
    for _ in range(count):
        frame, centre = rng.integers(frames), rng.integers(n)
        patch = np.argpartition(np.sum((surface - surface[centre]) ** 2, axis=1), size - 1)[:size]
        direction = rng.normal(size=3)
        points[frame, patch] += (noise.pop_cm * direction / np.linalg.norm(direction)).astype(np.float32)
        popped[frame, patch] = True
    return popped


def _drop_frames(points: np.ndarray, noise: TrackerNoise, rng) -> np.ndarray:
    frames = len(points)
    valid = np.ones(frames, dtype=bool)
    count = int(round(noise.drop_rate * frames))
    if count == 0 or frames < 2:
        return valid
    dropped = np.sort(rng.choice(np.arange(1, frames), size=min(count, frames - 1), replace=False))
    valid[dropped] = False
    for f in dropped:  # in order, so a run of drops repeats the last frame that was tracked
        points[f] = points[f - 1] if noise.drop_mode == "repeat" else np.nan
    return valid
