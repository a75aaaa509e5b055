"""The built-in face: a closed, outward-oriented quad head with two uv tiles and local expressions."""
import time

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from facedyn.sim.default_face import RESOLUTION, default_face
from facedyn.rig import LANDMARK_NAMES

ARKIT_SHAPES = {
    "jawOpen", "mouthSmile_L", "mouthSmile_R", "browInnerUp_L", "browInnerUp_R", "mouthPucker",
    "eyeBlink_L", "eyeBlink_R", "cheekPuff_L", "cheekPuff_R",
}


@pytest.fixture(scope="module")
def face():
    return default_face()


@pytest.fixture(scope="module", params=[6, 11, RESOLUTION])
def any_face(request):
    return default_face(request.param)


def half_edges(rig):
    """(H, 2) directed edges (a -> b) of every polygon, and each one's next edge in its polygon."""
    counts = rig.topology.face_vertex_counts.astype(np.int64)
    start = np.repeat(np.cumsum(counts) - counts, counts)
    corner = np.arange(counts.sum())
    following = start + (corner - start + 1) % np.repeat(counts, counts)
    indices = rig.topology.face_vertex_indices
    return np.stack([indices[corner], indices[following]], 1), following


def test_size_units_and_orientation_of_the_head(face):
    assert 3000 <= face.point_count <= 5000
    low, high = face.neutral.min(0), face.neutral.max(0)
    assert 19.0 <= high[1] - low[1] <= 23.0  # height (cm)
    assert 14.0 <= high[0] - low[0] <= 19.0  # width, ears included
    nose_tip = face.neutral[face.landmarks["nose_tip"]]
    assert nose_tip[2] == pytest.approx(high[2], abs=0.3)  # the face looks toward +Z
    assert set(face.topology.face_vertex_counts) == {4}


def test_generation_is_fast_and_deterministic(face):
    start = time.perf_counter()
    again = default_face()
    assert time.perf_counter() - start < 1.0
    np.testing.assert_array_equal(again.neutral, face.neutral)
    np.testing.assert_array_equal(again.topology.face_vertex_indices, face.topology.face_vertex_indices)
    np.testing.assert_array_equal(again.uvs.values, face.uvs.values)
    np.testing.assert_array_equal(again.identity_modes, face.identity_modes)
    for (i, a), (j, b) in zip(again.expression_offsets, face.expression_offsets):
        np.testing.assert_array_equal(i, j)
        np.testing.assert_array_equal(a, b)


def test_closed_and_consistently_oriented(any_face):
    """Every edge is used once in each direction: shared by exactly two faces that agree."""
    edges, _ = half_edges(any_face)
    keys = edges[:, 0] * any_face.point_count + edges[:, 1]
    reverse = edges[:, 1] * any_face.point_count + edges[:, 0]
    assert len(np.unique(keys)) == len(keys)
    assert np.isin(reverse, keys).all()
    assert (edges[:, 0] != edges[:, 1]).all()


def test_manifold_sphere(any_face):
    """One fan of faces around every vertex, one component, Euler characteristic 2."""
    edges, following = half_edges(any_face)
    n, h = any_face.point_count, len(edges)
    lookup = dict(zip((edges[:, 0] * n + edges[:, 1]).tolist(), range(h)))
    # Around vertex a: from half-edge a->b go to the twin of the edge entering a in the same face.
    previous = np.empty(h, np.int64)
    previous[following] = np.arange(h)
    twin_of_previous = np.array([lookup[b * n + a] for a, b in edges[previous].tolist()])
    rotation = sp.coo_matrix((np.ones(h), (np.arange(h), twin_of_previous)), shape=(h, h))
    fans, _ = connected_components(rotation, directed=True, connection="strong")
    assert fans == n
    vertex_graph = sp.coo_matrix((np.ones(h), (edges[:, 0], edges[:, 1])), shape=(n, n))
    assert connected_components(vertex_graph, directed=False)[0] == 1
    faces = len(any_face.topology.face_vertex_counts)
    assert n - h // 2 + faces == 2


def test_normals_point_outward(any_face):
    p = any_face.neutral.astype(np.float64)
    tri = any_face.topology.triangles()
    a, b, c = p[tri[:, 0]], p[tri[:, 1]], p[tri[:, 2]]
    volume = np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0
    assert volume > 0.0
    normals = np.cross(b - a, c - a)
    assert (np.einsum("ij,ij->i", normals, (a + b + c) / 3.0) > 0).all()  # star-shaped around the origin


def test_uvs_are_face_varying_on_two_tiles(any_face):
    uvs = any_face.uvs
    assert uvs.interpolation == "faceVarying"
    assert uvs.indices.shape == any_face.topology.face_vertex_indices.shape
    assert uvs.indices.min() == 0 and uvs.indices.max() == len(uvs.values) - 1
    st = uvs.values[uvs.indices].reshape(-1, 4, 2).astype(np.float64)
    assert (st[..., 1] > 0).all() and (st[..., 1] < 1).all()
    tiles = np.floor(st[..., 0])
    assert (tiles == tiles[:, :1]).all(), "a polygon straddles two uv tiles"
    assert set(np.unique(tiles)) == {0.0, 1.0}
    # No flipped polygon: every uv quad winds counter-clockwise, like the surface seen from outside.
    x, y = st[..., 0], st[..., 1]
    area = 0.5 * np.sum(x * np.roll(y, -1, 1) - np.roll(x, -1, 1) * y, axis=1)
    assert (area > 0).all()
    # The nose is on the face tile, the back of the head on the second one.
    poly = np.repeat(np.arange(len(tiles)), 4)
    nose_polys = poly[any_face.topology.face_vertex_indices == any_face.landmarks["nose_tip"]]
    back_polys = poly[any_face.topology.face_vertex_indices == np.argmin(any_face.neutral[:, 2])]
    assert (tiles[nose_polys, 0] == 0).all() and (tiles[back_polys, 0] == 1).all()


def test_expression_names_and_magnitudes(face):
    assert ARKIT_SHAPES <= set(face.expression_names)
    reach = {name: float(np.linalg.norm(face.dense_offsets(name), axis=1).max()) for name in face.expression_names}
    assert 2.0 <= reach["jawOpen"] <= 3.0
    for name, value in reach.items():
        if name != "jawOpen":
            assert 0.5 <= value <= 2.0, (name, value)


def test_expressions_are_local(face):
    x, y = face.neutral[:, 0], face.neutral[:, 1]
    for name in face.expression_names:
        moved = np.zeros(face.point_count, bool)
        moved[face.expression_offsets[face.shape_index(name)].indices] = True
        assert not moved[y > 5.0].any(), f"{name} moves the top of the head"
        if name.endswith("_L"):
            assert not moved[x < -1.0].any(), f"{name} moves the right side"
        if name.endswith("_R"):
            assert not moved[x > 1.0].any(), f"{name} moves the left side"
    blink = np.flatnonzero(np.any(face.dense_offsets("eyeBlink_L") != 0, axis=1))
    assert (x[blink] > 0).all() and (y[blink] > -2.0).all()
    jaw = np.flatnonzero(np.any(face.dense_offsets("jawOpen") != 0, axis=1))
    assert (y[jaw] < -1.0).all()  # below the jaw hinge


def test_left_and_right_shapes_mirror_each_other(face):
    mirror = np.array([-1.0, 1.0, 1.0])
    p = face.neutral
    order = np.lexsort((p[:, 2], p[:, 1], np.round(p[:, 0], 4)))
    twin = np.lexsort((p[:, 2], p[:, 1], np.round(-p[:, 0], 4)))
    np.testing.assert_allclose(p[order] * mirror, p[twin], atol=1e-4)
    left, right = face.dense_offsets("mouthSmile_L"), face.dense_offsets("mouthSmile_R")
    np.testing.assert_allclose(left[order] * mirror, right[twin], atol=1e-5)


def test_masks_and_landmarks(face):
    p = face.neutral
    assert set(face.landmarks) == set(LANDMARK_NAMES)
    lm = {name: p[i] for name, i in face.landmarks.items()}
    assert lm["eye_corner_left"][0] > lm["eye_inner_left"][0] > 0 > lm["eye_inner_right"][0] > lm["eye_corner_right"][0]
    assert lm["eye_corner_left"][0] == pytest.approx(-lm["eye_corner_right"][0], abs=1e-4)
    assert lm["nose_base"][1] < lm["nose_tip"][1] < lm["eye_inner_left"][1]
    face_set = set(face.face_vertices.tolist())
    assert {int(i) for i in face.landmarks.values()} <= face_set
    # Rigid skin never moves with an expression; the back of the head is rigid, the lips are not.
    moved = np.zeros(face.point_count, bool)
    for indices, _ in face.expression_offsets:
        moved[indices] = True
    assert not moved[face.rigid_vertices].any()
    assert np.argmin(p[:, 2]) in face.rigid_vertices
    np.testing.assert_array_equal(face.rigid_weights[face.rigid_vertices], 1.0)
    lips = np.flatnonzero(face.dense_offsets("mouthPucker")[:, 2] > 0.5)
    assert (face.rigid_weights[lips] == 0.0).all()
    assert ((face.rigid_weights > 0) & (face.rigid_weights < 1)).sum() > 50  # a soft falloff, not a step


def test_identity_modes_make_plausible_actors(face):
    assert face.identity_count >= 3
    reach = np.linalg.norm(face.identity_modes, axis=2).max(axis=1)
    assert (reach > 0.3).all() and (reach < 1.0).all()
    for c in (-2.5, 2.5):
        actor = face.make_actor(np.full(face.identity_count, c))
        tri = actor.topology.triangles()
        a, b, d = (actor.neutral[tri[:, k]].astype(np.float64) for k in range(3))
        normals = np.cross(b - a, d - a)
        assert (np.einsum("ij,ij->i", normals, (a + b + d) / 3.0) > 0).all()


def test_resolution_is_checked():
    with pytest.raises(ValueError, match="resolution must be an integer >= 6"):
        default_face(3)
    assert default_face(6).point_count == 6 * 36 + 2
