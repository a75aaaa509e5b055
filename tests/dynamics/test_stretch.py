"""Stretch features (papers/000 eq. 8): uv neighbourhoods, the formula, seams, tiles, real rig, OpenCL parity."""
from __future__ import annotations

import numpy as np
import pytest

from facedyn.dynamics.stretch import UVNeighbourhoods, difference_lengths, stretch_features
from facedyn.kernels import runtime
from facedyn.performance import Topology, UVs


def quad_grid(nx: int, ny: int, spacing: float = 0.1):
    """(points (nx*ny, 3) in the z = 0 plane, quad Topology, (nx*ny, 2) grid coordinates)."""
    ys, xs = np.mgrid[0:ny, 0:nx]
    coords = np.stack([xs.ravel(), ys.ravel()], axis=1).astype(np.float64)
    points = np.column_stack([coords * spacing, np.zeros(nx * ny)])
    a = (np.arange(ny - 1)[:, None] * nx + np.arange(nx - 1)[None, :]).ravel()
    quads = np.stack([a, a + 1, a + nx + 1, a + nx], axis=1)
    return points, Topology(np.full(len(quads), 4, np.int32), quads.ravel().astype(np.int32)), coords


def grid_vertex(nx: int, col: int, row: int) -> int:
    return row * nx + col


def cylinder(radius: float = 3.0, height: float = 4.0, around: int = 96, rows: int = 41, uv_form: str = "indexed"):
    """An open cylinder around z with a uv seam at angle 0 (u = 0 on one side, u = 1 on the other).

    Returns (points, topology, uvs, seam vertex indices). uv_form: 'indexed' faceVarying
    with shared values, or 'expanded' faceVarying with one value per corner.
    """
    theta = 2 * np.pi * np.arange(around) / around
    z = np.linspace(0.0, height, rows)
    angle, height_of = np.meshgrid(theta, z)
    points = np.stack([radius * np.cos(angle), radius * np.sin(angle), height_of], axis=-1).reshape(-1, 3)
    # uv grid has around + 1 columns: column `around` is the seam's second copy at u = 1.
    uv_values = np.stack(np.meshgrid(np.arange(around + 1) / around, z / height), axis=-1).reshape(-1, 2)
    r, c = np.meshgrid(np.arange(rows - 1), np.arange(around), indexing="ij")
    r, c = r.ravel(), c.ravel()
    vertex = lambda rr, cc: rr * around + cc % around  # noqa: E731
    uv = lambda rr, cc: rr * (around + 1) + cc  # noqa: E731
    fvi = np.stack([vertex(r, c), vertex(r, c + 1), vertex(r + 1, c + 1), vertex(r + 1, c)], axis=1).ravel()
    uv_indices = np.stack([uv(r, c), uv(r, c + 1), uv(r + 1, c + 1), uv(r + 1, c)], axis=1).ravel()
    topology = Topology(np.full(len(r), 4, np.int32), fvi.astype(np.int32))
    if uv_form == "indexed":
        uvs = UVs(uv_values.astype(np.float32), uv_indices.astype(np.int32), "faceVarying")
    else:
        uvs = UVs(uv_values[uv_indices].astype(np.float32), None, "faceVarying")
    return points, topology, uvs, np.arange(rows) * around


def scaled(points: np.ndarray, factors) -> np.ndarray:
    return points * np.asarray(factors, dtype=np.float64)


# --- the formula on a flat grid ---------------------------------------------------------

def test_flat_grid_uniform_stretch_along_u_gives_a_tenth_and_zero():
    nx = ny = 21
    points, topology, coords = quad_grid(nx, ny)  # 2 cm x 2 cm, 1 mm quads
    # u runs at 2 cm per uv unit, v at 4 cm: the uv step must follow each direction's own scale.
    uvs = UVs((coords * 0.1 / np.array([2.0, 4.0])).astype(np.float32), None, "vertex")
    samples = np.array([grid_vertex(nx, c, r) for c, r in [(10, 10), (5, 12), (14, 6)]])
    nb = UVNeighbourhoods.build(topology, uvs, points, samples)
    assert not nb.one_sided.any()
    np.testing.assert_allclose(nb.uv_steps[:, 0], 0.1, rtol=1e-5)
    np.testing.assert_allclose(nb.uv_steps[:, 1], 0.05, rtol=1e-5)
    np.testing.assert_allclose(difference_lengths(points, nb), 0.4, rtol=1e-5)
    frames = np.stack([points, scaled(points, [1.1, 1.0, 1.0]), scaled(points, [1.0, 0.8, 1.0])])
    s = stretch_features(frames, nb, backend="numpy")
    assert s.shape == (3, 3, 2) and s.dtype == np.float32
    np.testing.assert_allclose(s[0], 0.0, atol=1e-6)
    np.testing.assert_allclose(s[1], np.tile([0.1, 0.0], (3, 1)), atol=1e-5)
    np.testing.assert_allclose(s[2], np.tile([0.0, -0.2], (3, 1)), atol=1e-5)


def test_neutral_lengths_default_to_frame_0_and_can_come_from_a_separate_neutral():
    points, topology, coords = quad_grid(21, 21)
    nb = UVNeighbourhoods.build(topology, UVs(coords.astype(np.float32), None, "vertex"), points, [grid_vertex(21, 10, 10)])
    stretched = scaled(points, [1.1, 1.0, 1.0])
    from_frame_0 = stretch_features(np.stack([stretched, stretched]), nb, backend="numpy")
    np.testing.assert_allclose(from_frame_0, 0.0, atol=1e-6)
    from_neutral = stretch_features(stretched[None], nb, difference_lengths(points, nb), backend="numpy")
    np.testing.assert_allclose(from_neutral[0], [[0.1, 0.0]], atol=1e-5)


def test_a_sample_on_the_chart_border_uses_a_one_sided_difference_of_the_same_stretch():
    nx = 21
    points, topology, coords = quad_grid(nx, nx)
    corner, edge = grid_vertex(nx, 0, 0), grid_vertex(nx, 20, 10)
    nb = UVNeighbourhoods.build(topology, UVs(coords.astype(np.float32), None, "vertex"), points, [corner, edge])
    np.testing.assert_array_equal(nb.one_sided, [[True, True], [True, False]])
    np.testing.assert_allclose(difference_lengths(points, nb), [[0.2, 0.2], [0.2, 0.4]], rtol=1e-5)
    s = stretch_features(np.stack([points, scaled(points, [1.1, 0.9, 1.0])]), nb, backend="numpy")
    np.testing.assert_allclose(s[1], [[0.1, -0.1], [0.1, -0.1]], atol=1e-5)


# --- a curved surface and a seam --------------------------------------------------------

@pytest.mark.parametrize("uv_form", ["indexed", "expanded"])
def test_cylinder_under_radial_and_axial_stretch(uv_form):
    points, topology, uvs, seam = cylinder(uv_form=uv_form)
    samples = np.array([96 * 20 + 13, 96 * 10 + 50, 96 * 30 + 77])
    nb = UVNeighbourhoods.build(topology, uvs, points, samples)
    assert not nb.one_sided.any()
    lengths = difference_lengths(points, nb)
    np.testing.assert_allclose(lengths, 0.4, rtol=0.02)  # chords of 2 x 2 mm arcs on a polygonal cylinder
    # D_u of a point is horizontal, D_v vertical: widening the cylinder changes only u, lengthening only v.
    frames = np.stack([points, scaled(points, [1.05, 1.05, 1.0]), scaled(points, [1.0, 1.0, 0.9]), scaled(points, [0.95, 0.95, 1.2])])
    s = stretch_features(frames, nb, backend="numpy")
    expected = np.array([[0.0, 0.0], [0.05, 0.0], [0.0, -0.1], [-0.05, 0.2]])
    np.testing.assert_allclose(s, np.broadcast_to(expected[:, None, :], s.shape), atol=1e-5)


def test_a_sample_on_the_cylinder_seam_gets_a_correct_one_sided_u_difference():
    points, topology, uvs, seam = cylinder()
    sample = seam[20]  # angle 0, half way up: its corners have u = 0 on one side and u = 1 on the other
    nb = UVNeighbourhoods.build(topology, uvs, points, [sample])
    np.testing.assert_array_equal(nb.one_sided, [[True, False]])
    vertices, weights = nb.signed_weights()
    d_u = np.einsum("k,kc->c", weights[0, 0], points[vertices[0, 0]] - points[sample])
    # The one end that exists lies 2 mm along the circle: horizontal, tangent to it (its chord
    # leans inwards by half the angle it spans, 0.2 / 3 rad).
    assert abs(np.linalg.norm(d_u) - 0.2) < 0.01 * 0.2
    assert abs(d_u[2]) < 1e-9
    radial = points[sample] / np.linalg.norm(points[sample])
    assert abs(np.dot(d_u, radial)) / np.linalg.norm(d_u) < np.sin(0.2 / 3.0)
    frames = np.stack([points, scaled(points, [1.05, 1.05, 0.9])])
    np.testing.assert_allclose(stretch_features(frames, nb, backend="numpy")[1], [[0.05, -0.1]], atol=1e-5)


# --- uv tiles: two charts side by side in 1001 and 1002 ------------------------------------

def test_searches_never_cross_into_another_tile_chart():
    # Two separate sheets that continue each other in space and in uv: the left one fills
    # tile 1001 up to u = 1, the right one starts at u = 1 in tile 1002. Only a search that
    # crossed charts could find +u of a sample on the left sheet's right edge.
    nx = 11
    left, topology, coords = quad_grid(nx, nx)
    right = left + np.array([1.0, 0.0, 0.0])
    points = np.concatenate([left, right])
    n = len(left)
    indices = np.concatenate([topology.face_vertex_indices, topology.face_vertex_indices + n]).astype(np.int32)
    topology = Topology(np.tile(topology.face_vertex_counts, 2), indices)
    uv = coords / (nx - 1)
    uvs = UVs(np.concatenate([uv, uv + [1.0, 0.0]]).astype(np.float32), None, "vertex")
    samples = np.array([grid_vertex(nx, 10, 5), n + grid_vertex(nx, 0, 5), grid_vertex(nx, 5, 5), n + grid_vertex(nx, 5, 5)])
    nb = UVNeighbourhoods.build(topology, uvs, points, samples)
    assert nb.charts[0] == nb.charts[2] != nb.charts[1] == nb.charts[3]
    np.testing.assert_array_equal(nb.one_sided[:, 0], [True, True, False, False])
    on_left = nb.vertices < n
    assert on_left[[0, 2]].all() and not on_left[[1, 3]].any()
    s = stretch_features(np.stack([points, scaled(points, [1.1, 1.0, 1.0])]), nb, backend="numpy")
    np.testing.assert_allclose(s[1], np.tile([0.1, 0.0], (4, 1)), atol=1e-5)


# --- input checks ----------------------------------------------------------------------

def test_bad_inputs_raise_clear_errors():
    points, topology, coords = quad_grid(21, 21)
    uvs = UVs(coords.astype(np.float32), None, "vertex")
    with pytest.raises(ValueError, match="interpolation"):
        UVNeighbourhoods.build(topology, UVs(uvs.values, None, "uniform"), points, [5])
    with pytest.raises(ValueError, match="one entry per face-vertex corner"):
        UVNeighbourhoods.build(topology, UVs(uvs.values, np.zeros(3, np.int32), "faceVarying"), points, [5])
    with pytest.raises(ValueError, match="vertex indices"):
        UVNeighbourhoods.build(topology, uvs, points, [len(points)])
    with pytest.raises(ValueError, match="smaller step"):
        UVNeighbourhoods.build(topology, uvs, points, [grid_vertex(21, 10, 10)], step=5.0)
    nb = UVNeighbourhoods.build(topology, uvs, points, [grid_vertex(21, 10, 10)])
    with pytest.raises(ValueError, match="arrays shaped"):
        UVNeighbourhoods(nb.samples, nb.vertices[:, :1], nb.weights, nb.one_sided, nb.uv_steps, nb.charts, nb.step)
    with pytest.raises(ValueError, match="backend"):
        stretch_features(points[None], nb, backend="cuda")
    with pytest.raises(ValueError, match=r"\(F, N, 3\)"):
        stretch_features(points, nb)
    with pytest.raises(ValueError, match="neutral_lengths"):
        stretch_features(points[None], nb, np.ones((2, 2)))
    with pytest.raises(ValueError, match="positive"):
        stretch_features(points[None], nb, np.zeros((1, 2)))
    with pytest.raises(ValueError, match="vertices"):
        stretch_features(points[None, :10], nb)


# --- OpenCL parity ---------------------------------------------------------------------

@pytest.mark.parametrize("backend", ["numpy", "opencl"])
def test_compact_neighbourhoods_read_the_same_stretch_from_the_used_vertices_alone(backend):
    if backend == "opencl":
        opencl_or_skip()
    points, topology, uvs, seam = cylinder()
    nb = UVNeighbourhoods.build(topology, uvs, points, np.arange(5, len(points), 211))
    used, compact = nb.compact()
    assert len(used) < len(points) / 4 and np.array_equal(used, np.unique(used))
    assert np.array_equal(used[compact.samples], nb.samples) and np.array_equal(used[compact.vertices], nb.vertices)
    rng = np.random.default_rng(5)
    frames = (points[None] * rng.uniform(0.8, 1.2, (6, 1, 3)) + rng.normal(0, 0.02, (6,) + points.shape)).astype(np.float32)
    neutral = difference_lengths(points, nb)
    assert np.array_equal(stretch_features(frames[:, used], compact, neutral, backend=backend),
                          stretch_features(frames, nb, neutral, backend=backend))


def opencl_or_skip():
    reason = runtime.unavailable_reason()
    if reason is not None:
        pytest.skip(f"no OpenCL device: {reason}")


def test_opencl_matches_numpy_on_a_deforming_cylinder():
    opencl_or_skip()
    points, topology, uvs, seam = cylinder()
    samples = np.arange(0, len(points), 37)
    nb = UVNeighbourhoods.build(topology, uvs, points, samples)
    rng = np.random.default_rng(3)
    frames = points[None] * rng.uniform(0.8, 1.2, (40, 1, 3)) + rng.normal(0, 0.02, (40,) + points.shape) + [5.0, -8.0, 12.0]
    neutral = difference_lengths(points + [5.0, -8.0, 12.0], nb)
    expected = stretch_features(frames, nb, neutral, backend="numpy")
    got = stretch_features(frames, nb, neutral, backend="opencl")
    # 1e-5 relative on |D(t)| / |D(0)| = 1 + s.
    np.testing.assert_allclose(1.0 + got, 1.0 + expected, rtol=1e-5, atol=0)
    auto = stretch_features(frames, nb, neutral, backend="auto")
    np.testing.assert_allclose(1.0 + auto, 1.0 + expected, rtol=1e-5, atol=0)


# --- the ICT rig -----------------------------------------------------------------------

@pytest.fixture(scope="module")
def ict(shared_data):
    path = shared_data / "ict-facekit" / "ict_face_rig.usdc"
    if not path.is_file():
        pytest.skip(f"the ICT rig is not at {path}")
    rig_io = pytest.importorskip("facedyn.usd.blendshape_rig", reason="facedyn.usd.blendshape_rig (the rig reader) is not in this checkout")
    from facedyn.dynamics.samples import farthest_point_samples

    rig = rig_io.read_blendshape_rig(path)
    samples = farthest_point_samples(rig.neutral, rig.topology.triangles(), 344, rig.face_vertices)
    return rig, UVNeighbourhoods.build(rig.topology, rig.uvs, rig.neutral, samples)


def test_ict_neighbourhoods_are_2mm_either_side_of_344_face_samples(ict):
    rig, nb = ict
    assert nb.sample_count == 344
    assert np.unique(rig.uvs.values[:, 0] // 1).size >= 2  # the rig really has several tiles
    assert nb.one_sided.mean() < 0.2  # only samples at the face's chart borders, eyes and mouth
    lengths = difference_lengths(rig.neutral, nb)
    two_sided = lengths[~nb.one_sided]
    assert abs(np.median(two_sided) - 0.4) < 0.01
    assert np.mean((two_sided > 0.3) & (two_sided < 0.45)) > 0.95
    assert np.all(lengths[nb.one_sided] > 0.1)


def test_ict_jaw_open_stretches_the_mouth_and_chin_but_not_the_forehead(ict):
    rig, nb = ict
    jaw = rig.evaluate(rig.weights_from({"jawOpen": 1.0}))
    s = stretch_features(np.stack([rig.neutral, jaw]), nb, backend="numpy")[1]
    magnitude = np.abs(s).max(axis=1)
    moved = np.linalg.norm(jaw - rig.neutral, axis=1)[nb.samples]
    mouth_and_chin = moved > 1.0
    eyes_y = rig.neutral[[rig.landmarks["eye_corner_left"], rig.landmarks["eye_corner_right"]], 1].mean()
    forehead = rig.neutral[nb.samples, 1] > eyes_y + 2.5
    assert mouth_and_chin.sum() > 20 and forehead.sum() > 20
    assert np.median(magnitude[mouth_and_chin]) > 0.1
    assert magnitude[forehead].max() < 0.02


def test_ict_opencl_matches_numpy(ict):
    opencl_or_skip()
    rig, nb = ict
    weights = np.random.default_rng(0).uniform(0.0, 0.5, (30, rig.expression_count))
    frames = rig.evaluate(weights)
    neutral = difference_lengths(rig.neutral, nb)
    expected = stretch_features(frames, nb, neutral, backend="numpy")
    got = stretch_features(frames, nb, neutral, backend="opencl")
    np.testing.assert_allclose(1.0 + got, 1.0 + expected, rtol=1e-5, atol=0)
