"""Laplacian propagation of sample offsets, and the batched Laplacian on both backends."""
import numpy as np
import pytest
from opencl_marks import BACKENDS, requires_opencl
from scipy.sparse.csgraph import dijkstra
from synthetic_face import curved_sheet, top_rows

from facedyn.dynamics.propagate import build_propagator, laplacian_apply
from facedyn.dynamics.samples import farthest_point_samples
from facedyn.geometry.mesh import cotangent_laplacian
from facedyn.geometry.mesh_topology import edge_graph

ROWS, COLS = 24, 20


@pytest.fixture(scope="module")
def sheet():
    pts, topo = curved_sheet(ROWS, COLS)
    tri = topo.triangles()
    rigid = top_rows(ROWS, COLS, 3)
    samples = farthest_point_samples(pts, tri, 30, np.setdiff1d(np.arange(len(pts)), rigid))
    return pts, tri, rigid, samples, build_propagator(pts, tri, samples, rigid)


def test_exact_at_samples_and_still_on_the_rigid_region(sheet):
    pts, tri, rigid, samples, prop = sheet
    d = np.random.default_rng(0).normal(0, 0.3, (5, len(samples), 3)).astype(np.float32)
    u = prop.apply(d)
    assert u.shape == (5, len(pts), 3) and u.dtype == np.float32
    np.testing.assert_allclose(u[:, samples], d, atol=1e-6)
    assert np.all(u[:, rigid] == 0)


def test_smoother_than_a_nearest_sample_interpolant(sheet):
    pts, tri, rigid, samples, prop = sheet
    d = np.random.default_rng(1).normal(0, 0.3, (3, len(samples), 3)).astype(np.float32)
    smooth = prop.apply(d)
    nearest = np.argmin(dijkstra(edge_graph(pts, tri), directed=False, indices=samples), axis=0)
    blocky = d[:, nearest]
    blocky[:, rigid] = 0.0  # same constraints: exact at samples, still on the rigid region
    np.testing.assert_allclose(blocky[:, samples], d)
    assert np.all(prop.residual(smooth, "numpy") < 0.5 * prop.residual(blocky, "numpy"))


def test_constant_offsets_away_from_the_rigid_region_stay_constant():
    pts, topo = curved_sheet(12, 10)
    tri = topo.triangles()
    samples = np.array([0, 9, 55, 110, 119])
    prop = build_propagator(pts, tri, samples)  # no rigid region: constants are reproduced
    u = prop.apply(np.tile([0.1, -0.2, 0.3], (1, 5, 1)))
    np.testing.assert_allclose(u[0], np.tile([0.1, -0.2, 0.3], (len(pts), 1)), atol=1e-5)


def test_a_piece_without_samples_stays_still():
    pts, topo = curved_sheet(8, 8)
    tri = topo.triangles()
    both = np.concatenate([pts, pts + [0.0, 0.0, 20.0]])
    prop = build_propagator(both, np.concatenate([tri, tri + 64]), np.array([3, 20, 40]))
    u = prop.apply(np.ones((1, 3, 3), np.float32))
    assert np.all(u[0, 64:] == 0) and np.all(np.abs(u[0, :64]) > 0)


@pytest.mark.parametrize("backend", BACKENDS)
def test_batched_laplacian_matches_dense_reference(backend):
    pts, topo = curved_sheet(15, 12)
    lap = cotangent_laplacian(pts, topo.triangles())
    u = np.random.default_rng(2).normal(size=(7, len(pts), 3)).astype(np.float32)
    expected = np.einsum("ij,fjc->fic", lap.toarray(), u.astype(np.float64))
    out = laplacian_apply(lap, u, backend)
    assert out.shape == u.shape and out.dtype == np.float32
    np.testing.assert_allclose(out, expected, rtol=0, atol=1e-5 * np.abs(expected).max())


@requires_opencl
def test_opencl_laplacian_matches_scipy_on_many_frames(sheet):
    _, _, _, _, prop = sheet
    u = np.random.default_rng(3).normal(size=(64, prop.matrix.shape[0], 3)).astype(np.float32)
    ref = laplacian_apply(prop.laplacian, u, "numpy")
    out = laplacian_apply(prop.laplacian, u, "opencl")
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-5 * np.abs(ref).max())
    np.testing.assert_allclose(prop.residual(u, "opencl"), prop.residual(u, "numpy"), rtol=1e-5)


def test_bad_input_is_a_clear_error(sheet):
    pts, tri, rigid, samples, prop = sheet
    with pytest.raises(ValueError, match="both a sample and rigid"):
        build_propagator(pts, tri, np.append(samples, rigid[0]), rigid)
    with pytest.raises(ValueError, match="sample offsets"):
        prop.apply(np.zeros((2, len(samples) + 1, 3)))
    with pytest.raises(ValueError, match="u must be"):
        laplacian_apply(prop.laplacian, np.zeros((2, 5, 3)), "numpy")
