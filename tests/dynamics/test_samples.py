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


def face_with_teeth_and_seam():
    """The built-in face plus what real rigs carry: a closed 'teeth' box inside the mouth
    (its own mesh piece and uv chart) and a uv seam down the middle of the face."""
    from facedyn.performance import Topology, UVs
    from facedyn.sim.default_face import default_face

    rig = default_face()
    n = rig.point_count
    counts, indices = rig.topology.face_vertex_counts, rig.topology.face_vertex_indices
    corner_uv = np.asarray(rig.uvs.indices)
    values = np.asarray(rig.uvs.values)
    # seam: corners of the face's left-side polygons (x < 0) get their own copy of the uvs
    polygon = np.repeat(np.arange(len(counts)), counts)
    centre_x = np.bincount(polygon, weights=rig.neutral[indices, 0]) / counts
    left = (centre_x[polygon] < 0) & (rig.neutral[indices, 2] > 0)
    corner_uv = np.where(left, corner_uv + len(values), corner_uv)
    values = np.concatenate([values, values + [0.0, 1.0]])
    # teeth: a 3 x 1 x 1 cm box behind the lips, six quads
    box = np.array([[x, y, z] for x in (-1.5, 1.5) for y in (-6.5, -5.5) for z in (5.5, 6.5)], np.float32)
    quads = np.array([[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]])
    points = np.concatenate([rig.neutral, box])
    topology = Topology(np.concatenate([counts, np.full(6, 4, np.int32)]), np.concatenate([indices, quads.ravel() + n]).astype(np.int32))
    teeth_uv = np.concatenate([values, [[5.2, 0.2], [5.8, 0.2], [5.8, 0.8], [5.2, 0.8]]])
    uvs = UVs(teeth_uv.astype(np.float32), np.concatenate([corner_uv, np.tile(np.arange(4) + len(values), 6)]).astype(np.int32), "faceVarying")
    teeth = np.arange(n, n + 8)
    weights = np.concatenate([rig.rigid_weights, np.zeros(8, np.float32)])
    return points, topology, uvs, weights, np.concatenate([rig.face_vertices, teeth]), teeth


def test_samples_stay_on_the_outer_skin_and_off_uv_seams():
    from facedyn.dynamics.stretch import UVNeighbourhoods
    from facedyn.dynamics.samples import BORDER_REACH_CM, _seam_vertices, face_region
    from facedyn.geometry.mesh_topology import graph_distance

    points, topology, uvs, weights, face_vertices, teeth = face_with_teeth_and_seam()
    face = FaceSetup.build(topology, points, rigid_weights=weights, face_vertices=face_vertices, uvs=uvs)
    assert len(face.samples) == 344 and not np.isin(face.samples, teeth).any()
    seam = _seam_vertices(topology, uvs)
    assert np.intersect1d(seam, face_vertices).size > 20  # the seam does cross the face
    distance = graph_distance(points, topology.triangles(), seam)
    assert distance[face.samples].min() >= BORDER_REACH_CM
    neighbourhoods = UVNeighbourhoods.build(topology, uvs, points, face.samples)  # no sample lost off its chart
    assert not neighbourhoods.one_sided.any()
    # the plain face region (what samples were drawn from before) puts samples on the teeth
    region = np.setdiff1d(face_region(len(points), face_vertices), face.rigid_vertices)
    assert np.isin(farthest_point_samples(points, topology.triangles(), 344, region), teeth).any()


def test_skin_region_keeps_the_face_piece():
    from facedyn.dynamics.samples import skin_region

    points, topology, uvs, _, face_vertices, teeth = face_with_teeth_and_seam()
    kept = skin_region(points, topology, uvs, face_vertices)
    assert not np.isin(kept, teeth).any() and len(kept) > 0.7 * len(face_vertices)
    assert np.array_equal(kept, skin_region(points, topology, uvs, face_vertices))
    with pytest.raises(ValueError, match="outer skin"):
        skin_region(points, topology, uvs, teeth[:1], reach=100.0)


def test_ict_samples_build_their_stretch_stencils(shared_data):
    from facedyn.dynamics.stretch import UVNeighbourhoods
    from facedyn.usd.blendshape_rig import read_blendshape_rig

    rig = read_blendshape_rig(shared_data / "ict-facekit" / "ict_face_rig.usdc")
    face = FaceSetup.build(rig.topology, rig.neutral, rigid_weights=rig.rigid_weights, face_vertices=rig.face_vertices, uvs=rig.uvs)
    assert len(face.samples) == 344
    neighbourhoods = UVNeighbourhoods.build(rig.topology, rig.uvs, rig.neutral, face.samples)
    assert neighbourhoods.one_sided.mean() < 0.05
