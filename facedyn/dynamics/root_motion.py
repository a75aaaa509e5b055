"""Root-motion retargeting between actors (papers/000 §7.3), on arrays.

The paper retargets dynamics by giving actor B the skull motion of actor A and letting B's
own synthesis network H make B's dynamics (facedyn.dynamics.synthesis); its baseline copies
A's per-vertex offsets onto B. This module does the two array steps around that:

- `align_trajectory` moves A's skull trajectory T_A(t) into B's skull space. The two skull
  spaces are related by G, the rigid transform that best fits A's rest points onto B's
  corresponding rest points (same topology: same vertex indices; or the two models'
  landmarks, which `default_landmarks` places at the same bounding-box fractions). B then
  moves so that every point of its head does what the corresponding point of A's did:

      T_B(t) = S G T_A(0)^-1 T_A(t) G^-1

  with S = T_B(0), B's skull transform at the first frame. By default S = T_A(0) G^-1,
  which gives T_B(t) = T_A(t) G^-1: B's head exactly where A's head was. A rotation of A
  about its own head is therefore a rotation of B about B's corresponding point, not
  about B's skull origin, wherever each actor's skull space happens to put its origin.
  Only T_B(k)^-1 T_B(k-1) = G T_A(k)^-1 T_A(k-1) G^-1 reaches the skull features B(t), so
  S changes where B stands in the world but not the dynamics synthesized for it. B keeps
  its own landmarks (those of its model).
- `delta_transfer` is the naive baseline: B's quasistatic skin plus A's offsets at the same
  vertex indices, optionally rotated into B's skull axes by G's rotation.
- `residual_transfer` adds to B's synthesis what A's removal found beyond A's own model's
  synthesis under A's skull (rotated like delta transfer's offsets): the part of A's
  dynamics that a model reading the skull cannot say.
"""
from __future__ import annotations

import numpy as np

from facedyn.dynamics.skull import check_points, check_transforms
from facedyn.geometry import quaternion, rigid


def skull_correspondence(source_rest, target_rest, vertices=None) -> tuple[np.ndarray, np.ndarray]:
    """G = (rotation (3, 3), translation (3,)): A's skull space -> B's, fitted on rest points.

    source_rest, target_rest: (N, 3) corresponding skull-space points of A and B; vertices:
    the indices to fit on (default all; the rigid region, which sits on the bone, is the
    natural choice). A rigid least-squares fit, without scale.
    """
    a = np.asarray(source_rest, dtype=np.float64)
    b = np.asarray(target_rest, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3 or a.shape != b.shape:
        raise ValueError(f"source and target rest points must both be (N, 3) with the same N, got {a.shape} and {b.shape}")
    if vertices is not None:
        idx = np.asarray(vertices)
        if idx.ndim != 1 or not np.issubdtype(idx.dtype, np.integer) or idx.size == 0 or idx.min() < 0 or idx.max() >= len(a):
            raise ValueError(f"vertices must be a non-empty 1-D array of indices in [0, {len(a)})")
        a, b = a[idx], b[idx]
    spread = np.linalg.svd(a - a.mean(axis=0), compute_uv=False) if len(a) >= 3 else np.zeros(2)
    if spread[1] <= 1e-9 * max(spread[0], np.finfo(float).tiny):
        raise ValueError("the correspondence needs at least 3 points not all on one line")
    return rigid.kabsch(a, b)


def align_trajectory(translate, orient, source_rest, target_rest, *, vertices=None, start=None) -> tuple[np.ndarray, np.ndarray]:
    """B's skull trajectory (translate (F, 3), orient (F, 4) w x y z) from A's (see the module).

    translate/orient: A's skull T_A(t); source_rest/target_rest/vertices: the corresponding
    points that fix G (`skull_correspondence`); start: B's skull transform at the first
    frame as (translate (3,), orient (4,)), default the one that puts B's head where A's is.
    """
    t_a, q_a = check_transforms(translate, orient)
    rot_g, t_g = skull_correspondence(source_rest, target_rest, vertices)
    q_g = quaternion.from_matrix(rot_g)
    # G^-1 = (R_g^T, -R_g^T t_g); T_A(t) G^-1 = (R_A R_g^T, t_A - R_A R_g^T t_g)
    q_b = quaternion.multiply(q_a, quaternion.conjugate(q_g))
    t_b = t_a - quaternion.rotate(q_b, t_g)
    if start is not None:
        t_s, q_s = _start_transform(start)
        # Left-multiply by S T_B(0)^-1, which carries B's default first pose to `start`.
        q_fix = quaternion.multiply(q_s, quaternion.conjugate(q_b[0]))
        t_fix = t_s - quaternion.rotate(q_fix, t_b[0])
        q_b = quaternion.multiply(q_fix[None], q_b)
        t_b = quaternion.rotate(q_fix[None], t_b) + t_fix
    return t_b, quaternion.make_continuous(quaternion.normalize(q_b))


def delta_transfer(source_offsets, target_quasistatic, rotation=None) -> tuple[np.ndarray, np.ndarray]:
    """(points = B's quasistatic + A's offsets, offsets), float32, B's skull space.

    source_offsets: A's (F, N, 3) skull-frame offsets; target_quasistatic: B's (F, N, 3)
    skull-space quasistatic skin on the same topology; rotation: (3, 3) from A's skull
    axes to B's (G's rotation from `skull_correspondence`), default none.
    """
    d = check_points(source_offsets, "source offsets")
    y = check_points(target_quasistatic, "target quasistatic")
    if d.shape != y.shape:
        raise ValueError(f"source offsets {d.shape} and target quasistatic {y.shape} must have the same frames and vertices")
    offsets = _turned(d, rotation)
    return np.asarray(y, dtype=np.float32) + offsets, offsets


def residual_transfer(points, offsets, source_offsets, source_synthesized, rotation=None) -> tuple[np.ndarray, np.ndarray]:
    """(points, offsets) of B's synthesis (points, offsets: (F, N, 3) skull space) plus A's residual:
    A's removed offsets less what A's own model synthesized for A's quasistatic take (both
    (F, N, 3), A's skull frame), turned into B's axes by `rotation` as in `delta_transfer`."""
    removed = check_points(source_offsets, "source offsets")
    own = check_points(source_synthesized, "source synthesized offsets")
    if removed.shape != own.shape:
        raise ValueError(f"source offsets {removed.shape} and source synthesized offsets {own.shape} must have the same shape")
    residual = _turned(removed - own, rotation)
    if residual.shape != np.shape(offsets) or np.shape(points) != np.shape(offsets):
        raise ValueError(f"the residual {residual.shape} does not fit the synthesis' points {np.shape(points)} and offsets {np.shape(offsets)}")
    return np.asarray(points, np.float32) + residual, np.asarray(offsets, np.float32) + residual


def _turned(offsets: np.ndarray, rotation) -> np.ndarray:
    """(F, N, 3) float32 offsets turned by a (3, 3) proper rotation (None: as they are)."""
    turned = np.array(offsets, dtype=np.float32)
    if rotation is None:
        return turned
    rot = np.asarray(rotation, dtype=np.float64)
    if rot.shape != (3, 3) or not np.allclose(rot @ rot.T, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0:
        raise ValueError(f"rotation must be a (3, 3) proper rotation matrix, got {rot.shape}")
    return np.matmul(turned, rot.T.astype(np.float32))


def _start_transform(start) -> tuple[np.ndarray, np.ndarray]:
    try:
        t, q = (np.asarray(value, dtype=np.float64) for value in start)
    except (TypeError, ValueError):
        raise ValueError("start must be a pair (translate (3,), orient (4,))") from None
    if t.shape != (3,) or q.shape != (4,):
        raise ValueError(f"start must be (translate (3,), orient (4,)), got shapes {t.shape} and {q.shape}")
    t, q = check_transforms(t[None], q[None], 1)
    return t[0], quaternion.normalize(q[0])
