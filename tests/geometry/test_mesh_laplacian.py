"""Mesh operators: hand-computed values, algebraic properties, and robustness."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

from facedyn.geometry import mesh


def flat_grid(n: int, spacing: float = 1.0, jitter: float = 0.0, seed: int = 0):
    """An n x n planar grid of right triangles (optionally jittered) in the z = 0 plane."""
    xs, ys = np.meshgrid(np.arange(n) * spacing, np.arange(n) * spacing, indexing="ij")
    points = np.stack([xs.ravel(), ys.ravel(), np.zeros(n * n)], axis=1)
    interior = ((xs > 0) & (xs < (n - 1) * spacing) & (ys > 0) & (ys < (n - 1) * spacing)).ravel()
    points[interior, :2] += np.random.default_rng(seed).uniform(-jitter, jitter, (interior.sum(), 2)) * spacing
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    triangles = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return points, triangles, interior


def icosphere(subdivisions: int):
    """A unit sphere: icosahedron, each triangle split in four per level (vectorized)."""
    t = (1 + 5**0.5) / 2
    points = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                       [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], float)
    tris = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
                     [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
                     [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    for _ in range(subdivisions):
        edges = mesh.unique_edges(tris)
        mid = len(points) + np.arange(len(edges))
        points = np.concatenate([points, 0.5 * (points[edges[:, 0]] + points[edges[:, 1]])])
        lookup = {tuple(e): m for e, m in zip(edges.tolist(), mid)}
        e01, e12, e20 = (np.array([lookup[tuple(sorted(p))] for p in tris[:, pair].tolist()])
                         for pair in ([0, 1], [1, 2], [2, 0]))
        tris = np.concatenate([np.stack([tris[:, 0], e01, e20], 1), np.stack([tris[:, 1], e12, e01], 1),
                               np.stack([tris[:, 2], e20, e12], 1), np.stack([e01, e12, e20], 1)])
    return points / np.linalg.norm(points, axis=1, keepdims=True), tris


def test_right_triangle_by_hand():
    # 90 degrees at vertex 0, 45 at vertices 1 and 2: cot = 0, 1, 1
    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    tri = np.array([[0, 1, 2]])
    np.testing.assert_allclose(mesh.corner_cotangents(points, tri), [[0.0, 1.0, 1.0]], atol=1e-15)
    expected = np.array([[1.0, -0.5, -0.5], [-0.5, 0.5, 0.0], [-0.5, 0.0, 0.5]])
    np.testing.assert_allclose(mesh.cotangent_laplacian(points, tri).toarray(), expected, atol=1e-15)
    # Voronoi cells of a right triangle: the circumcentre is the hypotenuse's midpoint
    np.testing.assert_allclose(mesh.vertex_areas(points, tri), [0.25, 0.125, 0.125])
    np.testing.assert_allclose(mesh.vertex_areas(points, tri, "barycentric"), [1 / 6] * 3)
    np.testing.assert_allclose(mesh.mass_matrix(points, tri).diagonal(), [0.25, 0.125, 0.125])


def test_obtuse_triangle_by_hand():
    # angle at vertex 2 is obtuse: cot = -3/4; cot = 2 at vertices 0 and 1
    points = np.array([[0.0, 0, 0], [4, 0, 0], [2, 1, 0]])
    tri = np.array([[0, 1, 2]])
    np.testing.assert_allclose(mesh.corner_cotangents(points, tri), [[2.0, 2.0, -0.75]])
    lap = mesh.cotangent_laplacian(points, tri).toarray()
    np.testing.assert_allclose(lap[0, 1], 0.375)  # -w_01, w_01 = cot(2) / 2 < 0
    np.testing.assert_allclose(lap[0, 2], -1.0)
    np.testing.assert_allclose(lap[1, 2], -1.0)
    clamped = mesh.cotangent_laplacian(points, tri, nonnegative=True).toarray()
    assert clamped[0, 1] == 0.0 and clamped[0, 2] == -1.0
    np.testing.assert_allclose(clamped.sum(axis=1), 0.0, atol=1e-15)
    # mixed area: half the triangle (area 2) to the obtuse corner, a quarter to the others
    np.testing.assert_allclose(mesh.vertex_areas(points, tri), [0.5, 0.5, 1.0])


def test_uniform_laplacian_by_hand():
    tri = np.array([[0, 1, 2], [0, 2, 3]])  # a square split along 0-2
    expected = np.array([[3, -1, -1, -1], [-1, 2, -1, 0], [-1, -1, 3, -1], [-1, 0, -1, 2]], float)
    np.testing.assert_array_equal(mesh.uniform_laplacian(tri).toarray(), expected)
    assert mesh.uniform_laplacian(tri, n_points=6).shape == (6, 6)  # isolated points: zero rows
    np.testing.assert_array_equal(mesh.unique_edges(tri), [[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]])


@pytest.mark.parametrize("nonnegative", [False, True])
def test_laplacian_properties_on_a_sphere(nonnegative):
    points, tris = icosphere(2)
    lap = mesh.cotangent_laplacian(points, tris, nonnegative=nonnegative)
    assert sp.issparse(lap) and lap.shape == (len(points), len(points))
    assert abs(lap - lap.T).max() < 1e-12
    np.testing.assert_allclose(np.asarray(lap.sum(axis=1)).ravel(), 0.0, atol=1e-12)
    assert np.linalg.eigvalsh(lap.toarray()).min() > -1e-10  # positive semidefinite
    if nonnegative:
        assert (lap - sp.diags(lap.diagonal())).max() <= 0.0  # an M-matrix
    areas = mesh.vertex_areas(points, tris)
    assert np.all(areas > 0)
    np.testing.assert_allclose(areas.sum(), mesh.triangle_areas(points, tris).sum())
    np.testing.assert_allclose(areas.sum(), 4 * np.pi, rtol=0.02)  # the inscribed polyhedron's area
    # the Laplace-Beltrami of a coordinate on the unit sphere is -2 x: M^-1 L x ~ 2 x
    x = points[:, 2]
    np.testing.assert_allclose((lap @ x) / areas, 2 * x, atol=0.1)


@pytest.mark.parametrize("jitter", [0.0, 0.3])
def test_linear_functions_are_harmonic_on_a_flat_grid(jitter):
    points, tris, interior = flat_grid(12, spacing=0.5, jitter=jitter)
    lap = mesh.cotangent_laplacian(points, tris)
    linear = 3.0 * points[:, 0] - 2.0 * points[:, 1] + 0.7
    np.testing.assert_allclose((lap @ linear)[interior], 0.0, atol=1e-12)
    assert np.abs(lap @ linear)[~interior].max() > 1e-3  # the boundary is not harmonic
    areas = mesh.vertex_areas(points, tris, "barycentric")
    np.testing.assert_allclose(areas.sum(), (11 * 0.5) ** 2)
    if jitter == 0.0:
        np.testing.assert_allclose(mesh.vertex_areas(points, tris)[interior], 0.25)  # spacing^2


def test_degenerate_triangles_add_nothing():
    points, tris, _ = flat_grid(4)
    points = np.concatenate([points, [[1.0, 1.0, 0.0], [2.0, 2.0, 0.0]]])  # on vertex 5, and in line
    sliver = np.array([[5, 16, 17], [16, 16, 3]])  # zero area, and a repeated vertex
    lap = mesh.cotangent_laplacian(points, np.concatenate([tris, sliver]))
    assert np.all(np.isfinite(lap.data))
    clean = mesh.cotangent_laplacian(points[:16], tris).toarray()
    np.testing.assert_allclose(lap[:16, :16].toarray(), clean, atol=1e-12)
    areas = mesh.vertex_areas(points, np.concatenate([tris, sliver]))
    assert np.all(np.isfinite(areas)) and areas[16] == 0.0 and areas[17] == 0.0
    assert len(mesh.unique_edges(sliver)) == 4  # the repeated vertex's self-edge is dropped


def test_build_is_vectorized_and_fast():
    import time

    points, tris = icosphere(5)  # 10,242 points, 20,480 triangles
    started = time.perf_counter()
    lap = mesh.cotangent_laplacian(points, tris)
    mesh.vertex_areas(points, tris)
    mesh.uniform_laplacian(tris)
    assert time.perf_counter() - started < 2.0
    assert lap.nnz == len(points) + 2 * len(mesh.unique_edges(tris))


@pytest.mark.parametrize(
    "points, tris, message",
    [
        (np.zeros((3, 2)), np.array([[0, 1, 2]]), "points must be"),
        (np.zeros((3, 3)), np.array([0, 1, 2]), "triangles must be"),
        (np.zeros((3, 3)), np.array([[0, 1, 3]]), "indices must lie"),
        (np.zeros((3, 3)), np.array([[0.0, 1.0, 2.0]]), "integer"),
    ],
)
def test_bad_input_is_a_clear_error(points, tris, message):
    with pytest.raises(ValueError, match=message):
        mesh.cotangent_laplacian(points, tris)


def test_unknown_area_kind_is_an_error():
    with pytest.raises(ValueError, match="voronoi"):
        mesh.vertex_areas(np.eye(3), np.array([[0, 1, 2]]), kind="circumcentric")
