"""A headless triangle rasterizer in NumPy: review frames without OpenGL or a display.

Render farms and CI have no GPU context, so review images are rasterized on arrays. All
triangles are expanded at once into the rows of their bounding boxes, each row into the
span of pixels whose centres lie inside (bounded by the barycentrics), and the
front-most triangle per pixel is chosen with ``np.minimum.at`` over packed (depth,
triangle) keys. The same `rasterize` bakes uv maps (`facedyn.preview.uvmaps`), where the
"screen" is a uv tile.

Conventions: pixel (x, y) has its centre at (x + 0.5, y + 0.5), y grows downward; a pixel
belongs to a triangle when its centre lies inside (edges inclusive, ties go to the
nearer, then to the lower triangle index). Colours are interpolated affinely in screen
space (Gouraud); depth is interpolated as 1/z, which is exact under perspective.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facedyn.preview.colormap import BACKGROUND
from facedyn.geometry.mesh import VertexNormals, face_normals, normalize

# Inside-test tolerance in barycentric units: pixel centres on a shared edge must not fall
# through the crack between two triangles because of rounding.
_EPS = 1e-5
_NEAR = 1e-6
_NO_KEY = np.iinfo(np.int64).max
_BATCH = 1 << 22


@dataclass(frozen=True)
class Camera:
    """A pinhole camera. View space looks down -Z with +Y up; images have y down."""

    rotation: np.ndarray  # (3, 3) world -> view; rows are the view's right, up, back axes
    position: np.ndarray  # (3,) world position of the eye
    focal: float  # in pixels
    width: int
    height: int

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Pixel coordinates (N, 2) and view depth (N,) (positive in front of the eye)."""
        v = (np.asarray(points, dtype=np.float64) - self.position) @ self.rotation.T
        depth = -v[:, 2]
        safe = np.where(np.abs(depth) > _NEAR, depth, _NEAR)
        x = 0.5 * self.width + self.focal * v[:, 0] / safe
        y = 0.5 * self.height - self.focal * v[:, 1] / safe
        return np.stack([x, y], axis=1), depth

    def to_world(self, view_vector: np.ndarray) -> np.ndarray:
        """A direction given in view space (x right, y up, z toward the eye) in world space."""
        return np.asarray(view_vector, dtype=np.float64) @ self.rotation


def frame_camera(
    points: np.ndarray,
    yaw: float = 0.0,
    pitch: float = 0.0,
    width: int = 512,
    height: int = 512,
    fov: float = 25.0,
    margin: float = 1.05,
) -> Camera:
    """A camera that frames `points` (N, 3), or a whole sequence (F, N, 3), tightly.

    Framing on the whole sequence keeps the camera fixed while the face moves. The front
    view looks along -Z (the face looks toward +Z, Y up); `yaw` (degrees) orbits the eye
    around the vertical axis toward +X, `pitch` (degrees) raises it. The eye is then moved
    in its own image plane and distance so that the bounding box of the projected points
    is centred and fills the field of view (`fov`, vertical, degrees) shrunk by `margin`.
    """
    p = np.asarray(points)
    if p.ndim not in (2, 3) or p.shape[-1] != 3 or p.size == 0:
        raise ValueError(f"points must be a non-empty (N, 3) or (F, N, 3) array, got {p.shape}")
    if width < 1 or height < 1:
        raise ValueError(f"image size must be positive, got {width}x{height}")
    if not 0.0 < fov < 170.0 or margin <= 0.0:
        raise ValueError(f"fov must be in (0, 170) degrees and margin positive, got {fov}, {margin}")
    if not -89.0 <= pitch <= 89.0:
        raise ValueError(f"pitch must be within [-89, 89] degrees, got {pitch}")
    coords = np.ascontiguousarray(p.reshape(-1, 3).T, dtype=np.float64)  # (3, M): fast reductions
    if not np.isfinite(coords).all():
        raise ValueError("points contain NaN or infinite coordinates")
    centre = 0.5 * (coords.min(axis=1) + coords.max(axis=1))
    yw, pt = np.radians(yaw), np.radians(pitch)
    back = np.array([np.sin(yw) * np.cos(pt), np.sin(pt), np.cos(yw) * np.cos(pt)])
    right = normalize(np.cross([0.0, 1.0, 0.0], back))
    up = np.cross(back, right)
    rotation = np.stack([right, up, back])
    focal = 0.5 * height / np.tan(0.5 * np.radians(fov))
    local = rotation @ (coords - centre[:, None])  # (3, M) view-aligned, origin at the centre
    # Eye at centre + s*right + t*up + d*back. Point i fits horizontally when
    # |x_i - s| <= tan_x * (d - z_i); the smallest d for which some s fits all points is
    # closed-form, likewise vertically. At the larger of the two, each axis is centred.
    need = []
    for axis, tan in ((0, 0.5 * width / focal / margin), (1, 0.5 * height / focal / margin)):
        a = np.max(local[2] * tan + local[axis])
        b = np.max(local[2] * tan - local[axis])
        need.append((a + b) / (2 * tan))
    extent = max(np.ptp(local, axis=1).max(), 1e-9)
    distance = max(*need, local[2].max() + 1e-3 * extent)
    s, t = (_centre(local[axis], local[2], distance) for axis in (0, 1))
    eye = centre + s * right + t * up + distance * back
    return Camera(rotation, eye, float(focal), int(width), int(height))


def _centre(x: np.ndarray, z: np.ndarray, distance: float) -> float:
    """The eye offset s whose projections (x_i - s) / (distance - z_i) span a centred range.

    The span's midpoint decreases monotonically with s, so s is found by bisection. After
    a few steps on all points, only the points that can still be an extreme within the
    bracket are kept, which keeps framing a long sequence cheap.
    """
    a = 1.0 / (distance - z)
    ax = a * x
    lo, hi = float(x.min()), float(x.max())
    for step in range(64):
        if step == 8:
            at_lo, at_hi = ax - lo * a, ax - hi * a
            keep = (at_lo >= at_hi.max()) | (at_hi <= at_lo.min())
            a, ax = a[keep], ax[keep]
        mid = 0.5 * (lo + hi)
        v = ax - mid * a
        lo, hi = (mid, hi) if v.max() + v.min() > 0 else (lo, mid)
    return 0.5 * (lo + hi)


@dataclass
class Fragments:
    """The visible triangle at each covered pixel."""

    pixel: np.ndarray  # (K,) int64 flat index y * width + x
    triangle: np.ndarray  # (K,) int64 index into the triangle list
    bary: np.ndarray  # (K, 3) float32 barycentric weights of the triangle's corners
    width: int
    height: int

    def triangle_image(self) -> np.ndarray:
        """(height, width) int64 triangle index per pixel, -1 where nothing was drawn."""
        image = np.full(self.width * self.height, -1, dtype=np.int64)
        image[self.pixel] = self.triangle
        return image.reshape(self.height, self.width)


def rasterize(
    xy: np.ndarray, depth: np.ndarray | None, triangles: np.ndarray, width: int, height: int
) -> Fragments:
    """Visible triangle and barycentrics per pixel centre.

    `xy` (N, 2) pixel coordinates, `depth` (N,) positive view depth (None: all at the same
    depth, as for uv triangles), `triangles` (T, 3) vertex indices. Triangles with a corner
    at or behind the eye, and degenerate ones, are skipped.
    """
    xy = np.asarray(xy, dtype=np.float64)
    tris = np.asarray(triangles, dtype=np.int64)
    if xy.ndim != 2 or xy.shape[1] != 2:
        raise ValueError(f"xy must be (N, 2), got {xy.shape}")
    if tris.ndim != 2 or tris.shape[1] != 3:
        raise ValueError(f"triangles must be (T, 3), got {tris.shape}")
    if tris.size and (tris.min() < 0 or tris.max() >= len(xy)):
        raise ValueError(f"triangle indices must lie in [0, {len(xy)}), got [{tris.min()}, {tris.max()}]")
    if depth is None:
        inv_z = np.ones(len(xy))
    else:
        depth = np.asarray(depth, dtype=np.float64)
        if depth.shape != (len(xy),):
            raise ValueError(f"depth must be ({len(xy)},), got {depth.shape}")
        inv_z = 1.0 / np.maximum(depth, _NEAR)

    x, y, iz = xy[tris, 0], xy[tris, 1], inv_z[tris]  # (T, 3) each
    area2 = (x[:, 1] - x[:, 0]) * (y[:, 2] - y[:, 0]) - (x[:, 2] - x[:, 0]) * (y[:, 1] - y[:, 0])
    x0 = np.maximum(np.ceil(np.minimum(np.minimum(x[:, 0], x[:, 1]), x[:, 2]) - 0.5), 0)
    x1 = np.minimum(np.floor(np.maximum(np.maximum(x[:, 0], x[:, 1]), x[:, 2]) - 0.5), width - 1)
    y0 = np.maximum(np.ceil(np.minimum(np.minimum(y[:, 0], y[:, 1]), y[:, 2]) - 0.5), 0)
    y1 = np.minimum(np.floor(np.maximum(np.maximum(y[:, 0], y[:, 1]), y[:, 2]) - 0.5), height - 1)
    keep = (np.abs(area2) > 1e-12) & (x1 >= x0) & (y1 >= y0)
    if depth is not None:
        keep &= np.all(depth[tris] > _NEAR, axis=1)
    ids = np.flatnonzero(keep)
    x, y, iz, area2 = x[ids], y[ids], iz[ids], area2[ids]
    x0, y0 = x0[ids].astype(np.int64), y0[ids].astype(np.int64)
    bw = x1[ids].astype(np.int64) - x0 + 1
    bh = y1[ids].astype(np.int64) - y0 + 1

    # Barycentrics of corners 0 and 1 and 1/z are affine in the pixel offsets (dx, dy)
    # from the box's first pixel centre: columns of `coef` hold each one's value there and
    # its steps per pixel in x and in y (one row per triangle, so gathers move whole rows).
    cx, cy = x0 + 0.5, y0 + 0.5
    coef = np.empty((len(ids), 9))
    for k, (i, j) in enumerate(((1, 2), (2, 0))):
        coef[:, 3 * k] = ((x[:, i] - cx) * (y[:, j] - cy) - (x[:, j] - cx) * (y[:, i] - cy)) / area2
        coef[:, 3 * k + 1] = (y[:, i] - y[:, j]) / area2
        coef[:, 3 * k + 2] = (x[:, j] - x[:, i]) / area2
    dz0, dz1 = iz[:, 0] - iz[:, 2], iz[:, 1] - iz[:, 2]
    coef[:, 6] = iz[:, 2] + dz0 * coef[:, 0] + dz1 * coef[:, 3]
    coef[:, 7] = dz0 * coef[:, 1] + dz1 * coef[:, 4]
    coef[:, 8] = dz0 * coef[:, 2] + dz1 * coef[:, 5]

    # Depth test in batches of about _BATCH box pixels, so that memory stays bounded when
    # a few triangles cover a large uv tile. Keys pack the depth (nearer, i.e. larger
    # positive 1/z, i.e. larger float bits, first) above the triangle's index (lower
    # first), so that one minimum per pixel picks the winner deterministically.
    zbuf = np.full(width * height, _NO_KEY, dtype=np.int64)
    ends = np.cumsum(bw * bh)
    cuts = np.unique(np.searchsorted(ends, np.arange(_BATCH, ends[-1] if len(ends) else 0, _BATCH), side="right"))
    for lo, hi in zip(np.r_[0, cuts], np.r_[cuts, len(ids)]):
        if hi > lo:
            pix, inv_depth, tri = _spans(coef[lo:hi], x0[lo:hi], y0[lo:hi], bw[lo:hi], bh[lo:hi], width)
            bits = np.maximum(inv_depth, np.float32(1e-30)).view(np.int32).astype(np.int64)
            np.minimum.at(zbuf, pix, (-bits << 32) + (tri + lo))

    pixel = np.flatnonzero(zbuf != _NO_KEY)
    tri = zbuf[pixel] & 0xFFFFFFFF
    dx, dy = pixel % width - x0[tri], pixel // width - y0[tri]
    c = np.take(coef, tri, axis=0)
    bary = np.empty((len(pixel), 3), dtype=np.float32)
    bary[:, 0] = c[:, 0] + c[:, 1] * dx + c[:, 2] * dy
    bary[:, 1] = c[:, 3] + c[:, 4] * dx + c[:, 5] * dy
    bary[:, 2] = 1.0 - bary[:, 0] - bary[:, 1]
    return Fragments(pixel, ids[tri], bary, int(width), int(height))


def _spans(coef, x0, y0, bw, bh, width):
    """Pixels whose centres lie inside the given triangles, found as one x-span per box row.

    Along a row each barycentric is affine in x, so each bounds x from one side and the
    pixels inside are exactly the span between the bounds: no pixel is tested, and none
    outside is generated. Returns flat pixel index, 1/z (float32) and triangle (row of
    `coef`) per pixel.
    """
    tri = np.repeat(np.arange(len(bh)), bh)
    dy = np.arange(len(tri)) - np.repeat(np.cumsum(bh) - bh, bh)
    c = np.repeat(coef, bh, axis=0)
    first = np.zeros(len(tri))
    last = np.repeat(bw - 1, bh).astype(np.float64)
    empty = np.zeros(len(tri), dtype=bool)
    b0, b1 = c[:, 0] + c[:, 2] * dy, c[:, 3] + c[:, 5] * dy
    for start, step in ((b0, c[:, 1]), (b1, c[:, 4]), (1.0 - b0 - b1, -c[:, 1] - c[:, 4])):
        with np.errstate(divide="ignore", invalid="ignore"):
            bound = (-_EPS - start) / step
        first = np.where(step > 0, np.maximum(first, np.ceil(bound)), first)
        last = np.where(step < 0, np.minimum(last, np.floor(bound)), last)
        empty |= (step == 0) & (start < -_EPS)
    n = np.where(empty, 0, np.maximum(last - first + 1, 0)).astype(np.int64)
    first = np.where(n > 0, first, 0.0)
    local = np.arange(n.sum(), dtype=np.int64) - np.repeat(np.cumsum(n) - n, n)
    row_start = (np.repeat(y0, bh) + dy) * width + np.repeat(x0, bh) + first.astype(np.int64)
    z_start = (c[:, 6] + c[:, 7] * first + c[:, 8] * dy).astype(np.float32)
    inv_depth = np.repeat(z_start, n) + np.repeat(c[:, 7].astype(np.float32), n) * local.astype(np.float32)
    return np.repeat(row_start, n) + local, inv_depth, np.repeat(tri, n)


class Renderer:
    """Renders frames of one mesh through one camera.

    Built once per sequence (topology and camera fixed); `render` is then called per
    frame. Lighting is a two-sided Lambert key light placed up and to the left of the eye,
    so that the shape reads in both smooth and flat shading.
    """

    def __init__(
        self,
        triangles: np.ndarray,
        point_count: int,
        camera: Camera,
        shading: str = "smooth",
        background: tuple[float, float, float] = BACKGROUND,
        ambient: float = 0.25,
    ):
        if shading not in ("smooth", "flat"):
            raise ValueError(f"shading must be 'smooth' or 'flat', got {shading!r}")
        self.normals = VertexNormals(triangles, point_count, np.float32)
        self.triangles = self.normals.triangles
        self.camera = camera
        self.shading = shading
        self.background = np.clip(np.asarray(background, dtype=np.float64), 0, 1)
        self.ambient = float(ambient)
        self.light = normalize(camera.to_world([-0.35, 0.45, 1.0]))

    def render(self, points: np.ndarray, colors: np.ndarray | None = None) -> np.ndarray:
        """One frame: (height, width, 3) uint8 RGB.

        `points` (N, 3); `colors` (N, 3) per-vertex base colours in [0, 1] (None: light
        grey). Flat shading gives each triangle the mean of its corners' colours.
        """
        n = self.normals.point_count
        p = np.asarray(points, dtype=np.float64)
        if p.shape != (n, 3):
            raise ValueError(f"points must be ({n}, 3), got {p.shape}")
        if not np.isfinite(p).all():
            raise ValueError("points contain NaN or infinite coordinates")
        base = np.full((n, 3), 0.78) if colors is None else np.asarray(colors, dtype=np.float64)
        if base.shape != (n, 3):
            raise ValueError(f"colors must be ({n}, 3), got {base.shape}")
        cam = self.camera
        xy, depth = cam.project(p)
        frags = rasterize(xy, depth, self.triangles, cam.width, cam.height)
        if self.shading == "smooth":
            lit = self.shade(p, base).astype(np.float32)
            rgb = np.einsum("kc,kcj->kj", frags.bary, lit[self.triangles][frags.triangle])
        else:
            fn = normalize(face_normals(p, self.triangles))
            face_rgb = base[self.triangles].mean(axis=1) * self._lambert(fn)[:, None]
            rgb = face_rgb.astype(np.float32)[frags.triangle]
        image = np.empty((cam.width * cam.height, 3), dtype=np.float32)
        image[:] = self.background
        image[frags.pixel] = rgb
        np.clip(image, 0.0, 1.0, out=image)
        image *= 255.0
        image += 0.5
        return image.astype(np.uint8).reshape(cam.height, cam.width, 3)

    def shade(self, points: np.ndarray, colors: np.ndarray) -> np.ndarray:
        """Lit vertex colours (N, 3) of smooth shading: colour times Lambert of the vertex normal."""
        return colors * self._lambert(self.normals(points))[:, None]

    def _lambert(self, normals: np.ndarray) -> np.ndarray:
        return self.ambient + (1.0 - self.ambient) * np.abs(normals @ self.light)
