"""Errors against ground truth, as the benchmarks, the demo and the closing notes report them.

Stabilization: skull space is defined only up to one rigid transform (the rest frame is a
free choice), so the solved skull-space sequence is aligned to the true one by a single
global rigid transform before vertex, rotation and translation errors are measured.
Dynamics: residuals are RMS over face vertices and frames, as a fraction of the true
dynamics' RMS, so "do nothing" scores 100%.
"""
from __future__ import annotations

import numpy as np

from facedyn.geometry import quaternion, rigid


def implied_skull_transforms(solved_translate: np.ndarray, solved_orient: np.ndarray, true_translate: np.ndarray,
                             true_orient: np.ndarray, true_skull: np.ndarray, vertices: np.ndarray | None = None):
    """Solved skull transforms expressed in the true skull frame, and that frame change.

    true_skull: (F, N, 3) the noise-free skin in true skull space; translate/orient map
    skull to world. The true world skin is taken into the solved skull space with the
    solved transforms; that sequence is aligned to the true one by one global rigid
    transform G (over ``vertices``), and the solved skull transform then corresponds to
    T_solved G^-1. Returns (rotation (F, 3, 3), translate (F, 3), G as (rot, trans),
    the aligned solved skin (F*V, 3), the true skin (F*V, 3)).
    """
    world = np.einsum("fij,fnj->fni", quaternion.to_matrix(true_orient), true_skull) + true_translate[:, None]
    r_s = quaternion.to_matrix(solved_orient)
    solved_skull = np.einsum("fji,fnj->fni", r_s, world - solved_translate[:, None])
    vertices = np.arange(true_skull.shape[1]) if vertices is None else np.asarray(vertices)
    source = solved_skull[:, vertices].reshape(-1, 3).astype(np.float64)
    target = true_skull[:, vertices].reshape(-1, 3).astype(np.float64)
    g_rot, g_trans = rigid.kabsch(source, target)
    # Solved skull -> world is R_s x + t_s; in true skull coordinates x = G^-1 y, so the
    # implied skull transform is R_s G_r^T y + (t_s - R_s G_r^T g_t).
    r_solved = r_s @ g_rot.T
    t_solved = solved_translate - np.einsum("fij,j->fi", r_solved, g_trans)
    return r_solved, t_solved, (g_rot, g_trans), source @ g_rot.T + g_trans, target


def stabilization_errors(solved_translate: np.ndarray, solved_orient: np.ndarray, true_translate: np.ndarray,
                         true_orient: np.ndarray, true_skull: np.ndarray, vertices: np.ndarray | None = None) -> dict:
    """Vertex (cm), rotation (deg) and translation (cm) errors of solved skull transforms,
    measured in the true skull frame (implied_skull_transforms), so that the vertex error
    measures the transforms alone (not tracking noise)."""
    vertices = np.arange(true_skull.shape[1]) if vertices is None else np.asarray(vertices)
    r_solved, t_solved, _, aligned, target = implied_skull_transforms(
        solved_translate, solved_orient, true_translate, true_orient, true_skull, vertices)
    distance = np.linalg.norm(aligned - target, axis=1)
    r_true = quaternion.to_matrix(true_orient)
    relative = np.einsum("fji,fjk->fik", r_true, r_solved)
    angle = np.degrees(np.arccos(np.clip((np.trace(relative, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0)))
    # Translation error at the skull origin is arbitrary; measure it at the face's centroid.
    centre = true_skull[:, vertices].reshape(-1, 3).mean(axis=0)
    world_true = np.einsum("fij,j->fi", r_true, centre) + true_translate
    world_solved = np.einsum("fij,j->fi", r_solved, centre) + t_solved
    shift = np.linalg.norm(world_true - world_solved, axis=1)
    return {
        "median_vertex_cm": float(np.median(distance)),
        "mean_vertex_cm": float(np.mean(distance)),
        "p95_vertex_cm": float(np.percentile(distance, 95)),
        "mean_rotation_deg": float(np.mean(angle)),
        "max_rotation_deg": float(np.max(angle)),
        "mean_translation_cm": float(np.mean(shift)),
    }


def landmark_acceleration_error(solved_translate: np.ndarray, solved_orient: np.ndarray, true_translate: np.ndarray,
                                true_orient: np.ndarray, true_skull: np.ndarray, landmarks: np.ndarray, fps: float,
                                vertices: np.ndarray | None = None) -> float:
    """RMS error of the skull landmarks' accelerations in the skull frame (what the
    networks read, facedyn.dynamics.skull_motion) computed from the solved skull, as a
    fraction of their true RMS. landmarks: (L, 3) in true skull space."""
    from facedyn.dynamics.skull_motion import skull_accelerations

    r_solved, t_solved, *_ = implied_skull_transforms(
        solved_translate, solved_orient, true_translate, true_orient, true_skull, vertices)
    solved = skull_accelerations(t_solved, quaternion.from_matrix(r_solved), landmarks, fps)[1:-1]
    truth = skull_accelerations(true_translate, true_orient, landmarks, fps)[1:-1]
    return float(np.sqrt(np.mean((solved - truth) ** 2)) / np.sqrt(np.mean(truth**2)))


def skull_frame_disagreement(frame_a: tuple[np.ndarray, np.ndarray], frame_b: tuple[np.ndarray, np.ndarray],
                             points: np.ndarray) -> float:
    """Median distance (cm) between ``points`` (true skull space) taken into two solved
    skull frames, each given as the (rot, trans) G that implied_skull_transforms returns:
    how far two takes' skull spaces are apart (0 when they share one)."""
    (ra, ta), (rb, tb) = frame_a, frame_b
    pa = (np.asarray(points, dtype=np.float64) - ta) @ ra  # G_a^-1 y
    pb = (np.asarray(points, dtype=np.float64) - tb) @ rb
    return float(np.median(np.linalg.norm(pa - pb, axis=1)))


def residual_fraction(estimate: np.ndarray, truth: np.ndarray, true_offsets: np.ndarray, vertices: np.ndarray | None = None) -> dict:
    """RMS(estimate - truth) over the vertices, absolute (cm) and as a fraction of RMS(true offsets)."""
    vertices = np.arange(truth.shape[1]) if vertices is None else np.asarray(vertices)
    residual = np.sqrt(np.mean(np.sum((estimate[:, vertices] - truth[:, vertices]) ** 2, axis=-1)))
    dynamics = np.sqrt(np.mean(np.sum(true_offsets[:, vertices] ** 2, axis=-1)))
    return {"residual_rms_cm": float(residual), "dynamics_rms_cm": float(dynamics),
            "fraction": float(residual / dynamics) if dynamics > 0 else float("nan")}
