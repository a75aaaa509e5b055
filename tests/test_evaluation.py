"""Evaluation against truth: invariant to the free choice of skull space."""
import numpy as np

from facedyn.evaluation import residual_fraction, stabilization_errors
from facedyn.geometry import quaternion


def test_a_rigidly_shifted_skull_space_scores_zero():
    rng = np.random.default_rng(0)
    rest = rng.normal(scale=8.0, size=(50, 3))
    frames = 6
    true_orient = quaternion.from_rotvec(rng.normal(scale=0.2, size=(frames, 3)))
    true_translate = rng.normal(scale=5.0, size=(frames, 3))
    true_skull = np.repeat(rest[None], frames, 0) + rng.normal(scale=0.01, size=(frames, 50, 3))
    world = np.einsum("fij,fnj->fni", quaternion.to_matrix(true_orient), true_skull) + true_translate[:, None]
    # Another valid skull space: x' = G x with G a fixed rigid transform.
    g_q = quaternion.from_rotvec(np.array([0.1, -0.3, 0.2]))
    g_r, g_t = quaternion.to_matrix(g_q), np.array([1.0, -2.0, 0.5])
    solved_skull = true_skull @ g_r.T + g_t
    r_solved = quaternion.to_matrix(true_orient) @ g_r.T  # world = R_true G^-1 x'
    t_solved = true_translate - np.einsum("fij,j->fi", r_solved, g_t)
    np.testing.assert_allclose(np.einsum("fij,fnj->fni", r_solved, solved_skull) + t_solved[:, None], world, atol=1e-9)
    errors = stabilization_errors(t_solved, quaternion.from_matrix(r_solved), true_translate, true_orient, true_skull)
    assert errors["median_vertex_cm"] < 1e-9 and errors["mean_rotation_deg"] < 1e-5 and errors["mean_translation_cm"] < 1e-9
    # A real error shows up.
    tilted = quaternion.from_matrix(r_solved)
    tilted[3] = quaternion.multiply(quaternion.from_rotvec(np.array([0.0, 0.01, 0.0])), tilted[3])  # one frame off by 0.57 deg
    errors = stabilization_errors(t_solved, tilted, true_translate, true_orient, true_skull)
    assert abs(errors["max_rotation_deg"] - np.degrees(0.01)) < 0.1
    assert errors["median_vertex_cm"] > 1e-3


def test_residual_fraction_of_doing_nothing_is_one():
    rng = np.random.default_rng(1)
    truth = rng.normal(size=(4, 10, 3))
    offsets = rng.normal(scale=0.1, size=truth.shape)
    assert residual_fraction(truth + offsets, truth, offsets)["fraction"] == 1.0
    assert residual_fraction(truth, truth, offsets)["fraction"] == 0.0
