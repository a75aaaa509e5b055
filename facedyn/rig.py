"""A blend-shape face rig as arrays: an actor's neutral, masks and landmarks, and the simulator's shapes.

A `FaceRig` is a neutral mesh plus expression offsets (driven by ARKit-style curves) and
identity modes (which make new actors). It is data, not simulation, and plain NumPy:
`facedyn.usd.blendshape_rig` reads and writes it as a UsdSkel blend-shape rig (so `actor` and the
corpus files read a rig without loading the simulator), `facedyn.sim.default_face` builds
one in code, and the simulator (`facedyn.sim`) drives it.

Expression offsets are stored sparse, one `ShapeOffsets(indices, offsets)` per shape,
because real rigs move only part of the face per shape; evaluation stacks them once into a
single (K, 3N) basis so that any number of frames costs one matrix product.
"""
from __future__ import annotations

import difflib
from dataclasses import dataclass, field, replace
from functools import cached_property, partial
from typing import Mapping, NamedTuple, Sequence

import numpy as np
import scipy.sparse as sp

from facedyn.geometry.mesh_topology import graph_distance
from facedyn.performance import UVs, Topology

# Landmark names every rig provides when it can: the eye corners and the point under the nose
# are the classic three-point stabilization markers (papers/001, section IV).
LANDMARK_NAMES = ("eye_corner_left", "eye_corner_right", "eye_inner_left", "eye_inner_right", "nose_tip", "nose_base")

# Width (cm, along the skin) over which rigid weights fall from 1 on the rigid set to 0.
RIGID_FALLOFF_CM = 3.0

# Above this fraction of non-zeros a dense basis multiplies faster than a sparse one.
_DENSE_BASIS_FILL = 0.2


class ShapeOffsets(NamedTuple):
    """One sparse blend shape: the vertices it moves and by how much (cm)."""

    indices: np.ndarray  # (n,) int32, each vertex once
    offsets: np.ndarray  # (n, 3) float32


def sparse_offsets(dense: np.ndarray) -> ShapeOffsets:
    """Keep only the vertices a dense (N, 3) offset field actually moves."""
    dense = np.asarray(dense, dtype=np.float32)
    moved = np.flatnonzero(np.any(dense != 0.0, axis=1)).astype(np.int32)
    return ShapeOffsets(moved, dense[moved])


def rigid_falloff(points: np.ndarray, topology: Topology, rigid_vertices: np.ndarray, falloff: float = RIGID_FALLOFF_CM) -> np.ndarray:
    """(N,) float32 weights: 1 on the rigid vertices, easing to 0 at `falloff` cm along the skin.

    The ease is a smoothstep of the edge-graph distance, so the weights have no kink where
    bone-attached skin meets free soft tissue.
    """
    n = len(points)
    if len(rigid_vertices) == 0:
        return np.zeros(n, dtype=np.float32)
    distance = graph_distance(points, topology.triangles(), rigid_vertices, limit=falloff)
    t = np.clip(distance / falloff, 0.0, 1.0)
    return (1.0 - t * t * (3.0 - 2.0 * t)).astype(np.float32)


@dataclass(frozen=True, eq=False)
class FaceRig:
    """A neutral face, its expression shapes and identity modes, and the masks the simulator uses.

    All positions and offsets are in centimetres, Y up, face toward +Z. `expression_offsets`
    accepts a dense (K, N, 3) array or a sequence of (indices, offsets) pairs and is kept
    as a tuple of `ShapeOffsets`. Masks left as None get their generic meaning: the face is
    every vertex, no vertex is rigid, rigid weights follow `rigid_falloff`.
    """

    name: str
    neutral: np.ndarray  # (N, 3) float32
    topology: Topology
    uvs: UVs | None = None
    expression_names: tuple[str, ...] = ()
    expression_offsets: tuple[ShapeOffsets, ...] = ()
    identity_modes: np.ndarray | None = None  # (M, N, 3) float32
    face_vertices: np.ndarray | None = None  # int32
    rigid_vertices: np.ndarray | None = None  # int32
    rigid_weights: np.ndarray | None = None  # (N,) float32 in [0, 1]
    landmarks: dict[str, int] = field(default_factory=dict)
    metadata: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        set_ = partial(object.__setattr__, self)  # frozen dataclass: normalize the fields once, here
        neutral = np.asarray(self.neutral, dtype=np.float32)
        if neutral.ndim != 2 or neutral.shape[1] != 3 or len(neutral) == 0:
            raise ValueError(f"rig {self.name!r}: neutral must be (N, 3) points, got shape {neutral.shape}")
        n = len(neutral)
        set_("neutral", neutral)
        if self.topology.point_count > n:
            raise ValueError(f"rig {self.name!r}: topology uses vertex {self.topology.point_count - 1} but the neutral has {n} points")
        set_("expression_names", tuple(str(name) for name in self.expression_names))
        set_("expression_offsets", self._checked_shapes(self.expression_offsets, n))
        if len(set(self.expression_names)) != len(self.expression_names):
            raise ValueError(f"rig {self.name!r}: expression names repeat")
        modes = np.zeros((0, n, 3), np.float32) if self.identity_modes is None else np.asarray(self.identity_modes, dtype=np.float32)
        if modes.ndim != 3 or modes.shape[1:] != (n, 3):
            raise ValueError(f"rig {self.name!r}: identity modes must be (M, {n}, 3), got shape {modes.shape}")
        set_("identity_modes", modes)
        set_("face_vertices", self._checked_vertices("face_vertices", np.arange(n) if self.face_vertices is None else self.face_vertices, n))
        set_("rigid_vertices", self._checked_vertices("rigid_vertices", () if self.rigid_vertices is None else self.rigid_vertices, n))
        weights = self.rigid_weights
        weights = rigid_falloff(neutral, self.topology, self.rigid_vertices) if weights is None else np.asarray(weights, dtype=np.float32)
        if weights.shape != (n,) or not np.all((weights >= 0.0) & (weights <= 1.0)):
            raise ValueError(f"rig {self.name!r}: rigid weights must be {n} values in [0, 1]")
        set_("rigid_weights", weights)
        landmarks = {str(k): int(v) for k, v in self.landmarks.items()}
        bad = {k: v for k, v in landmarks.items() if not 0 <= v < n}
        if bad:
            raise ValueError(f"rig {self.name!r}: landmark vertices out of range [0, {n}): {bad}")
        set_("landmarks", landmarks)

    def _checked_shapes(self, shapes, n: int) -> tuple[ShapeOffsets, ...]:
        if isinstance(shapes, np.ndarray):
            if shapes.ndim != 3 or shapes.shape[1:] != (n, 3):
                raise ValueError(f"rig {self.name!r}: dense expression offsets must be (K, {n}, 3), got shape {shapes.shape}")
            shapes = [sparse_offsets(dense) for dense in shapes]
        if len(shapes) != len(self.expression_names):
            raise ValueError(f"rig {self.name!r}: {len(self.expression_names)} expression names for {len(shapes)} offset sets")
        checked = []
        for name, (indices, offsets) in zip(self.expression_names, shapes):
            indices = np.asarray(indices, dtype=np.int64)
            offsets = np.asarray(offsets, dtype=np.float32)
            if indices.ndim != 1 or offsets.shape != (len(indices), 3):
                raise ValueError(f"rig {self.name!r}: shape {name!r} has {len(indices)} indices but offsets of shape {offsets.shape}")
            if indices.size and (indices.min() < 0 or indices.max() >= n):
                raise ValueError(f"rig {self.name!r}: shape {name!r} moves vertices outside [0, {n})")
            if len(np.unique(indices)) != len(indices):
                raise ValueError(f"rig {self.name!r}: shape {name!r} lists a vertex more than once")
            checked.append(ShapeOffsets(indices.astype(np.int32), offsets))
        return tuple(checked)

    def _checked_vertices(self, what: str, vertices, n: int) -> np.ndarray:
        vertices = np.asarray(vertices, dtype=np.int64)
        if vertices.ndim != 1 or (vertices.size and (vertices.min() < 0 or vertices.max() >= n)):
            raise ValueError(f"rig {self.name!r}: {what} must be vertex indices in [0, {n})")
        return vertices.astype(np.int32)

    @property
    def point_count(self) -> int:
        return len(self.neutral)

    @property
    def expression_count(self) -> int:
        return len(self.expression_names)

    @property
    def identity_count(self) -> int:
        return len(self.identity_modes)

    def shape_index(self, name: str) -> int:
        """Column of expression `name` in a weight matrix."""
        try:
            return self.expression_names.index(name)
        except ValueError:
            close = difflib.get_close_matches(name, self.expression_names, n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else f"; it has {self.expression_count} expressions"
            raise ValueError(f"rig {self.name!r} has no expression {name!r}{hint}") from None

    def dense_offsets(self, name: str) -> np.ndarray:
        """(N, 3) offsets of one expression at weight 1."""
        indices, offsets = self.expression_offsets[self.shape_index(name)]
        dense = np.zeros((self.point_count, 3), np.float32)
        dense[indices] = offsets
        return dense

    def weights_from(self, curves: Mapping[str, float | Sequence[float] | np.ndarray]) -> np.ndarray:
        """A weight matrix from named curves: (K,) for scalars, (F, K) when any curve has F frames.

        Expressions not named stay 0; an unknown name is an error (drop curves the rig lacks first).
        """
        columns = {self.shape_index(name): np.asarray(value, dtype=np.float32) for name, value in curves.items()}
        lengths = {v.shape for v in columns.values() if v.ndim}
        if len(lengths) > 1 or any(len(shape) != 1 for shape in lengths):
            raise ValueError(f"rig {self.name!r}: curves must be scalars or 1-D of one length, got shapes {sorted(lengths)}")
        frames = lengths.pop() if lengths else ()
        weights = np.zeros(frames + (self.expression_count,), np.float32)
        for k, value in columns.items():
            weights[..., k] = value
        return weights

    @cached_property
    def _basis(self) -> np.ndarray | sp.csr_matrix:
        """(K, 3N) expression offsets: dense when mostly filled (faster BLAS), else CSR."""
        n, k = self.point_count, self.expression_count
        cols = np.concatenate([(3 * idx[:, None] + np.arange(3)).ravel() for idx, _ in self.expression_offsets])
        rows = np.repeat(np.arange(k), [3 * len(idx) for idx, _ in self.expression_offsets])
        vals = np.concatenate([off.ravel() for _, off in self.expression_offsets])
        if len(vals) > _DENSE_BASIS_FILL * k * 3 * n:
            dense = np.zeros((k, 3 * n), np.float32)
            dense[rows, cols] = vals
            return dense
        return sp.csr_matrix((vals, (rows, cols)), shape=(k, 3 * n), dtype=np.float32)

    def evaluate(self, weights: np.ndarray | Sequence[float]) -> np.ndarray:
        """Posed points: (K,) weights -> (N, 3), (F, K) -> (F, N, 3), neutral + weights @ offsets."""
        if self.expression_count == 0:
            raise ValueError(f"rig {self.name!r} has no expression shapes to evaluate")
        w = np.asarray(weights, dtype=np.float32)
        if w.ndim not in (1, 2) or w.shape[-1] != self.expression_count:
            raise ValueError(
                f"rig {self.name!r}: weights must be (K,) or (F, K) with K = {self.expression_count} expressions, got shape {w.shape}"
            )
        frames = np.atleast_2d(w)
        posed = np.asarray(frames @ self._basis).reshape(len(frames), self.point_count, 3)
        posed += self.neutral
        return posed[0] if w.ndim == 1 else posed

    def make_actor(
        self,
        coefficients: Sequence[float] | np.ndarray | None = None,
        *,
        seed: int | None = None,
        scale: float = 1.0,
        name: str | None = None,
    ) -> "FaceRig":
        """Another person: neutral + sum_k (scale * c_k) identity_k, expressions and masks kept.

        Give the M coefficients, or a seed to draw them from N(0, 1) (identity modes are
        scaled so that unit-variance coefficients give plausible faces).
        """
        if self.identity_count == 0:
            raise ValueError(f"rig {self.name!r} has no identity modes to make an actor from")
        if (coefficients is None) == (seed is None):
            raise ValueError("make_actor needs either coefficients or a seed (exactly one)")
        if coefficients is None:
            coefficients = np.random.default_rng(seed).standard_normal(self.identity_count)
        c = np.asarray(coefficients, dtype=np.float64)
        if c.shape != (self.identity_count,):
            raise ValueError(f"rig {self.name!r}: expected {self.identity_count} identity coefficients, got shape {c.shape}")
        c = scale * c
        neutral = self.neutral + np.tensordot(c, self.identity_modes, axes=1).astype(np.float32)
        actor_name = name or (f"{self.name}_actor{seed}" if seed is not None else f"{self.name}_actor")
        metadata = {**self.metadata, "base_rig": self.name, "identity_coefficients": c.tolist()}
        return replace(self, name=actor_name, neutral=neutral, metadata=metadata)


def alignment_vertices(rig: FaceRig) -> np.ndarray | None:
    """The rig's outer eye corners and under-nose vertex, when it names them."""
    names = ("eye_corner_left", "eye_corner_right", "nose_base")
    if not all(name in rig.landmarks for name in names):
        return None
    return np.array([rig.landmarks[name] for name in names], np.int32)
