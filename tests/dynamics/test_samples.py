"""Skin samples by farthest-point sampling and default skull landmarks."""
import numpy as np
import pytest
from scipy.sparse.csgraph import dijkstra
from synthetic_face import curved_sheet, top_rows

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.samples import LANDMARK_NAMES, check_landmarks, default_landmarks, farthest_point_samples
from facedyn.geometry.mesh_topology import edge_graph


def test_samples_are_spread_evenly_over_the_region():
    pts, topo = curved_sheet(30, 24)
    tri = topo.triangles()
    region = np.setdiff1d(np.arange(len(pts)), top_rows(30, 24, 4))
    samples = farthest_point_samples(pts, tri, 40, region)
    assert len(np.unique(samples)) == 40 and np.isin(samples, region).all()
    np.testing.assert_array_equal(samples, farthest_point_samples(pts, tri, 40, region))  # deterministic
    graph = edge_graph(pts, tri)[region][:, region]
    local = np.searchsorted(region, samples)
    dist = dijkstra(graph, directed=False, indices=local)
    covering = dist.min(axis=0).max()  # farthest any region vertex is from a sample
    pairwise = dist[:, local][~np.eye(40, dtype=bool)].min()
    # Farthest-point sampling: no two samples are closer than the covering radius.
    assert pairwise >= covering - 1e-9
    rng = np.random.default_rng(0)
    random = rng.choice(len(region), 40, replace=False)
    assert covering < dijkstra(graph, directed=False, indices=random).min(axis=0).max()


def test_every_piece_of_a_split_region_gets_samples():
    pts, topo = curved_sheet(10, 10)
    tri = topo.triangles()
    two = np.concatenate([pts, pts + [0.0, 0.0, 30.0]])
    samples = farthest_point_samples(two, np.concatenate([tri, tri + 100]), 6)
    assert (samples < 100).any() and (samples >= 100).any()


def test_default_landmarks_are_spread_and_documented():
    pts, _ = curved_sheet(20, 16)
    lms = default_landmarks(pts)
    assert lms.shape == (len(LANDMARK_NAMES), 3)
    assert np.linalg.matrix_rank(lms[1:] - lms[0]) == 3
    forehead, left, right = lms[0], lms[1], lms[2]
    assert forehead[1] > lms[4][1] and left[0] > 0 > right[0]


def test_face_setup_fills_defaults_outside_the_rigid_region():
    pts, topo = curved_sheet(20, 16)
    rigid_weights = np.zeros(len(pts))
    rigid_weights[top_rows(20, 16, 3)] = 1.0
    face = FaceSetup.build(topo, pts, rigid_weights=rigid_weights, sample_count=25)
    assert len(face.samples) == 25 and not np.isin(face.samples, top_rows(20, 16, 3)).any()
    np.testing.assert_array_equal(face.rigid_vertices, top_rows(20, 16, 3))
    with pytest.raises(ValueError, match="rigid region"):
        FaceSetup(topo, pts, face.rigid_vertices[:3], face.landmarks, face.rigid_vertices)


def test_bad_input_is_a_clear_error():
    pts, topo = curved_sheet(5, 5)
    with pytest.raises(ValueError, match="cannot place 30 samples"):
        farthest_point_samples(pts, topo.triangles(), 30)
    with pytest.raises(ValueError, match="collinear"):
        check_landmarks(np.outer(np.arange(5.0), [1.0, 2.0, 3.0]))
