"""The NumPy rasterizer: coverage, depth order, framing, shading, and the offset colours."""
import numpy as np
import pytest

from facedyn.preview import colormap
from facedyn.geometry.mesh import VertexNormals
from facedyn.preview.raster import Renderer, frame_camera, rasterize


def grid(nx, ny, width=2.0, height=2.0, jitter=0.0, seed=0):
    """A plane z = 0 facing +Z: (points, triangles), optionally with jittered interior points."""
    x, y = np.meshgrid(np.linspace(-width / 2, width / 2, nx), np.linspace(-height / 2, height / 2, ny))
    pts = np.stack([x, y, np.zeros_like(x)], -1).reshape(-1, 3)
    if jitter:
        inner = np.zeros((ny, nx), bool)
        inner[1:-1, 1:-1] = True
        rng = np.random.default_rng(seed)
        pts[inner.ravel(), :2] += rng.uniform(-jitter, jitter, (inner.sum(), 2)) * [width / nx, height / ny]
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1))
    a = (j * nx + i).ravel()
    tris = np.concatenate([np.stack([a, a + 1, a + nx + 1], 1), np.stack([a, a + nx + 1, a + nx], 1)])
    return pts, tris


def test_single_triangle_covers_exactly_the_pixel_centres_inside():
    frags = rasterize(np.array([[0.0, 0.0], [8.0, 0.0], [0.0, 8.0]]), None, np.array([[0, 1, 2]]), 10, 10)
    image = frags.triangle_image()
    y, x = np.mgrid[0:10, 0:10]
    assert np.array_equal(image == 0, (x + 0.5) + (y + 0.5) <= 8.0)
    # barycentrics reproduce the pixel centre
    px, py = frags.pixel % 10 + 0.5, frags.pixel // 10 + 0.5
    recon = frags.bary @ np.array([[0.0, 0.0], [8.0, 0.0], [0.0, 8.0]])
    np.testing.assert_allclose(recon, np.stack([px, py], 1), atol=1e-5)


def test_matches_a_brute_force_depth_test():
    rng = np.random.default_rng(3)
    w, h, t = 64, 48, 40
    xy = rng.uniform([-10, -10], [w + 10, h + 10], (3 * t, 2))
    depth = rng.uniform(1.0, 5.0, 3 * t)
    tris = np.arange(3 * t).reshape(t, 3)
    got = rasterize(xy, depth, tris, w, h).triangle_image()

    y, x = np.mgrid[0:h, 0:w]
    c = np.stack([x + 0.5, y + 0.5], -1).reshape(-1, 1, 2)
    p0, p1, p2 = xy[tris[:, 0]], xy[tris[:, 1]], xy[tris[:, 2]]
    area = (p1[:, 0] - p0[:, 0]) * (p2[:, 1] - p0[:, 1]) - (p2[:, 0] - p0[:, 0]) * (p1[:, 1] - p0[:, 1])

    def edge(a, b):
        return ((a[:, 0] - c[..., 0]) * (b[:, 1] - c[..., 1]) - (b[:, 0] - c[..., 0]) * (a[:, 1] - c[..., 1])) / area

    bary = np.stack([edge(p1, p2), edge(p2, p0), edge(p0, p1)], -1)  # (pixels, T, 3)
    inside = (bary >= 0).all(-1)
    inv_z = (bary * (1.0 / depth[tris])).sum(-1)
    score = np.where(inside, inv_z, -np.inf)
    want = np.where(inside.any(1), score.argmax(1), -1).reshape(h, w)
    clear = (np.abs(bary).min(-1) > 1e-6).all(1).reshape(h, w)  # no pixel centre on an edge
    assert clear.mean() > 0.9
    assert np.array_equal(got[clear], want[clear])
    assert (want >= 0).sum() > 1000


@pytest.mark.parametrize("order", [[0, 1], [1, 0]])
def test_nearer_triangle_wins_whatever_the_order(order):
    pts = np.array([[-1, -1, 0], [1, -1, 0], [0, 1, 0], [-1, -1, 0.5], [1, -1, 0.5], [0, 1, 0.5]], float)
    colors = np.repeat([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]], 3, axis=0)  # far red, near blue
    tris = np.array([[0, 1, 2], [3, 4, 5]])[order]
    renderer = Renderer(tris, 6, frame_camera(pts, width=64, height=64), ambient=1.0)
    image = renderer.render(pts, colors)
    r, g, b = image[32, 32].astype(int)
    assert b > 200 and r < 30


def test_a_jittered_surface_has_no_cracks_and_the_background_stays():
    pts, tris = grid(30, 30, jitter=0.3)
    cam = frame_camera(pts, width=128, height=128)
    xy, depth = cam.project(pts)
    image = rasterize(xy, depth, tris, 128, 128).triangle_image()
    lo, hi = np.ceil(xy.min(0)).astype(int) + 1, np.floor(xy.max(0)).astype(int) - 1
    assert (image[lo[1] : hi[1], lo[0] : hi[0]] >= 0).all()
    assert (image[:, : lo[0] - 2] == -1).all() and (image[:, hi[0] + 2 :] == -1).all()


def test_framing_centres_the_mesh_and_fills_the_frame():
    pts, _ = grid(11, 21, width=16.0, height=22.0)
    pts[:, 2] = 5.0 * np.cos(pts[:, 0] / 10.0)
    for yaw in (0.0, 35.0):
        cam = frame_camera(pts, yaw=yaw, width=200, height=100, margin=1.1)
        xy, depth = cam.project(pts)
        assert (depth > 0).all()
        lo, hi = xy.min(0), xy.max(0)
        assert (lo >= 0).all() and hi[0] <= 200 and hi[1] <= 100
        np.testing.assert_allclose((lo + hi) / 2, [100, 50], atol=1e-6)
        assert max((hi[0] - lo[0]) / 200, (hi[1] - lo[1]) / 100) == pytest.approx(1 / 1.1, rel=1e-6)
    front, side = frame_camera(pts), frame_camera(pts, yaw=35.0)
    assert front.position[2] > 0 and abs(front.position[0]) < 1e-9
    assert side.position[0] > 0


def test_offsets_toward_the_viewer_are_green_away_red_zero_grey():
    pts, tris = grid(31, 11, width=3.0, height=1.0)
    normals = VertexNormals(tris, len(pts), np.float32)(pts)
    sign = np.select([pts[:, 0] < -0.5, pts[:, 0] > 0.5], [1.0, -1.0], 0.0)
    offsets = 0.2 * sign[:, None] * normals  # 2 mm along the normal, which faces the camera
    mm = colormap.normal_component_mm(offsets, normals)
    np.testing.assert_allclose(mm, 2.0 * sign, atol=1e-6)
    renderer = Renderer(tris, len(pts), frame_camera(pts, width=96, height=32))
    image = renderer.render(pts, colormap.diverging(mm, 2.0)).astype(int)
    r, g, b = image[16, 10]
    assert g > r + 80 and g > b + 80
    r, g, b = image[16, 86]
    assert r > g + 80 and r > b + 80
    r, g, b = image[16, 48]
    assert max(r, g, b) - min(r, g, b) <= 2 and r > 60


def test_flat_shading_gives_one_colour_per_triangle_and_smooth_varies():
    theta, phi = np.meshgrid(np.linspace(0.2, 2.9, 12), np.linspace(0, 2 * np.pi, 25))
    pts = np.stack([np.sin(theta) * np.cos(phi), np.cos(theta), np.sin(theta) * np.sin(phi)], -1).reshape(-1, 3)
    _, tris = grid(12, 25)
    cam = frame_camera(pts, width=96, height=96)
    ids = rasterize(*cam.project(pts), tris, 96, 96).triangle_image().ravel()
    for shading, one_colour in (("flat", True), ("smooth", False)):
        image = Renderer(tris, len(pts), cam, shading=shading).render(pts).reshape(-1, 3)
        pairs = np.unique(np.column_stack([ids, image])[ids >= 0], axis=0)
        assert (len(pairs) == len(np.unique(ids[ids >= 0]))) == one_colour


def test_bad_input_is_refused():
    pts, tris = grid(3, 3)
    renderer = Renderer(tris, len(pts), frame_camera(pts, width=16, height=16))
    with pytest.raises(ValueError, match=r"points must be \(9, 3\)"):
        renderer.render(pts[:5])
    with pytest.raises(ValueError, match="colors"):
        renderer.render(pts, np.ones((9, 4)))
    with pytest.raises(ValueError, match="NaN"):
        renderer.render(np.full((9, 3), np.nan))
    with pytest.raises(ValueError, match="shading"):
        Renderer(tris, len(pts), renderer.camera, shading="phong")
    with pytest.raises(ValueError, match="triangle indices"):
        Renderer(tris, 4, renderer.camera)
    with pytest.raises(ValueError, match="points must be"):
        frame_camera(np.zeros((0, 3)))
