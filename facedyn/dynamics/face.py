"""What a dynamics model knows about the mesh it was trained on.

A model only works on the topology it was trained on, with the same skin samples, skull
landmarks and rigid region; `FaceSetup` keeps those together so the model file can store
them and removal can rebuild the propagation from them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facedyn.dynamics.samples import (SAMPLE_COUNT, RIGID_THRESHOLD, check_landmarks, default_landmarks, face_region, farthest_point_samples,
                                      skin_region)
from facedyn.performance import Performance, Topology


@dataclass
class FaceSetup:
    topology: Topology
    rest_points: np.ndarray  # (N, 3) skull space, the neutral frame
    samples: np.ndarray  # (S,) int32 skin sample vertices
    landmarks: np.ndarray  # (L, 3) skull-space skull landmarks
    rigid_vertices: np.ndarray  # (R,) int32 vertices that never move relative to the skull

    def __post_init__(self) -> None:
        self.rest_points = np.asarray(self.rest_points, dtype=np.float64)
        n = len(self.rest_points)
        if self.rest_points.ndim != 2 or self.rest_points.shape[1] != 3:
            raise ValueError(f"rest points must be (N, 3), got {self.rest_points.shape}")
        if self.topology.point_count > n:
            raise ValueError(f"the topology indexes {self.topology.point_count} points but the rest mesh has {n}")
        self.samples = _indices(self.samples, n, "skin samples")
        self.rigid_vertices = _indices(self.rigid_vertices, n, "rigid vertices")
        if len(np.unique(self.samples)) != len(self.samples):
            raise ValueError("skin samples must be distinct vertices")
        if len(self.samples) == 0:
            raise ValueError("a face setup needs at least one skin sample")
        overlap = np.intersect1d(self.samples, self.rigid_vertices)
        if overlap.size:
            raise ValueError(f"{overlap.size} skin samples lie in the rigid region (e.g. vertex {overlap[0]}); samples must be free to move")
        self.landmarks = check_landmarks(self.landmarks)

    @classmethod
    def build(
        cls,
        topology: Topology,
        rest_points,
        *,
        rigid_weights=None,
        rigid_vertices=None,
        face_vertices=None,
        samples=None,
        landmarks=None,
        sample_count: int = SAMPLE_COUNT,
        uvs=None,
    ) -> "FaceSetup":
        """Fill what is not given: rigid vertices from rigid weights >= RIGID_THRESHOLD,
        samples by farthest-point sampling of the face region's outer skin (default: the
        non-rigid vertices; see samples.skin_region, which `uvs` lets keep off uv seams),
        landmarks from the rest mesh's bounding box."""
        rest = np.asarray(rest_points, dtype=np.float64)
        n = len(rest)
        if rigid_vertices is None:
            if rigid_weights is not None:
                weights = np.asarray(rigid_weights, dtype=np.float64)
                if weights.shape != (n,):
                    raise ValueError(f"rigid weights must be ({n},), got {weights.shape}")
                rigid_vertices = np.flatnonzero(weights >= RIGID_THRESHOLD)
            else:
                rigid_vertices = np.zeros(0, np.int32)
        rigid = _indices(rigid_vertices, n, "rigid vertices")
        if samples is None:
            region = np.setdiff1d(face_region(n, face_vertices), rigid)
            if region.size == 0:
                raise ValueError("every face vertex is rigid: no vertex is left for skin samples")
            region = skin_region(rest, topology, uvs, region)
            samples = farthest_point_samples(rest, topology.triangles(), min(sample_count, len(region)), region)
        if landmarks is None:
            landmarks = default_landmarks(rest)
        return cls(topology, rest, samples, landmarks, rigid)

    @classmethod
    def from_performance(cls, performance: Performance, sample_count: int = SAMPLE_COUNT) -> "FaceSetup":
        """From a take's own setup arrays where it has them (rest points default to frame 0)."""
        rest = performance.rest_points if performance.rest_points is not None else performance.points[0]
        return cls.build(
            performance.topology,
            rest,
            rigid_weights=performance.rigid_weights,
            face_vertices=performance.face_vertices,
            samples=performance.skin_samples,
            landmarks=performance.landmarks,
            sample_count=sample_count,
            uvs=performance.uvs,
        )

    @property
    def point_count(self) -> int:
        return len(self.rest_points)

    @property
    def fingerprint(self) -> str:
        return self.topology.fingerprint()


def _indices(values, n: int, what: str) -> np.ndarray:
    idx = np.asarray(values)
    if idx.ndim != 1 or (idx.size and not np.issubdtype(idx.dtype, np.integer)):
        raise ValueError(f"{what} must be a 1-D array of vertex indices, got {idx.dtype} {idx.shape}")
    idx = idx.astype(np.int64)
    if idx.size and (idx.min() < 0 or idx.max() >= n):
        raise ValueError(f"{what} must lie in [0, {n}), got [{idx.min()}, {idx.max()}]")
    return idx.astype(np.int32)
