"""Review-image speed: 512x512 frames of face-sized meshes, and uv offset-map baking.

Prints one JSON object per case. Two meshes of the ICT face's size: a synthetic 74 x 152
displaced grid (11,248 points, 22,046 triangles) shaped like a face (a half ellipsoid with
a nose, one uv tile or split over two), and the built-in default head at resolution 43
(11,096 points, 22,188 triangles, closed, so hidden triangles are drawn too; two uv
tiles). Both are animated with small offsets, so every frame recomputes normals. The
reference is a per-triangle Python loop over the same mesh and camera.

    python benchmarks/bench_render.py [--frames 40] [--resolution 1024] [--out FILE] [--note TEXT]
"""
from __future__ import annotations

import os
import platform
import tempfile
import time

import numpy as np

from facedyn import __version__
from facedyn.performance import Topology, UVs
from facedyn.sim.default_face import default_face
from facedyn.preview import colormap
from facedyn.preview.raster import Renderer, frame_camera
from facedyn.preview.uvmaps import UVBaker, write_offset_maps

from harness import Recorder, parser

TARGET_FPS = 10.0


def synthetic_face(nx: int = 74, ny: int = 152):
    """(points (N, 3) cm, quads (Q, 4), uv per point (N, 2)) of a face-like displaced grid."""
    u, v = np.meshgrid(np.linspace(-1, 1, nx), np.linspace(-1, 1, ny))
    x, y = 8.0 * u, 11.0 * v
    z = 8.0 * np.sqrt(1 - 0.6 * (u**2 + v**2) + 0.3 * (u * v) ** 2)
    z += 2.5 * np.exp(-((x / 1.2) ** 2 + ((y + 1) / 2.5) ** 2))
    points = np.stack([x, y, z], -1).reshape(-1, 3).astype(np.float32)
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1))
    a = (j * nx + i).ravel()
    quads = np.stack([a, a + 1, a + nx + 1, a + nx], 1)
    uv = np.stack([(u + 1) / 2, (v + 1) / 2], -1).reshape(-1, 2)
    return points, quads, uv


def animated(points: np.ndarray, normals: np.ndarray, frames: int) -> np.ndarray:
    """(F, N, 3) offsets along the normals: a travelling wave of up to 2 mm."""
    phase = np.linspace(0, 2 * np.pi, frames, endpoint=False)[:, None]
    return (0.2 * np.sin(points[None, :, 1] * 0.8 + phase))[..., None] * normals[None]


def loop_reference(renderer: Renderer, points: np.ndarray, colors: np.ndarray) -> np.ndarray:
    """The same frame, one triangle at a time (the straightforward Python rasterizer)."""
    cam = renderer.camera
    xy, depth = cam.project(points)
    lit = renderer.shade(points, colors)
    zbuf = np.full((cam.height, cam.width), np.inf)
    image = np.zeros((cam.height, cam.width, 3))
    for tri in renderer.triangles:
        p = xy[tri]
        x0, y0 = np.maximum(np.ceil(p.min(0) - 0.5), 0).astype(int)
        x1, y1 = np.minimum(np.floor(p.max(0) - 0.5), [cam.width - 1, cam.height - 1]).astype(int)
        if x1 < x0 or y1 < y0:
            continue
        yy, xx = np.mgrid[y0 : y1 + 1, x0 : x1 + 1] + 0.5
        m = np.array([[p[0, 0] - p[2, 0], p[1, 0] - p[2, 0]], [p[0, 1] - p[2, 1], p[1, 1] - p[2, 1]]])
        if abs(np.linalg.det(m)) < 1e-12:
            continue
        b01 = np.linalg.solve(m, np.stack([xx.ravel() - p[2, 0], yy.ravel() - p[2, 1]]))
        b = np.vstack([b01, 1 - b01.sum(0)])
        inside = (b >= -1e-5).all(0)
        z = 1.0 / (b.T @ (1.0 / depth[tri]))
        py, px = yy.ravel()[inside].astype(int), xx.ravel()[inside].astype(int)
        nearer = z[inside] < zbuf[py, px]
        py, px = py[nearer], px[nearer]
        zbuf[py, px] = z[inside][nearer]
        image[py, px] = (b[:, inside][:, nearer].T @ lit[tri])
    return image


def bench_render(record: Recorder, mesh: str, points, topology, frames: int, reference: bool) -> None:
    tris = topology.triangles()
    for view, yaw in (("front", 0.0), ("three-quarter", 35.0)):
        normals = Renderer(tris, len(points), frame_camera(points)).normals(points)
        offsets = animated(points, normals, frames)
        sequence = points[None] + offsets
        camera = frame_camera(sequence, yaw=yaw, width=512, height=512)
        for shading in ("smooth", "flat"):
            renderer = Renderer(tris, len(points), camera, shading=shading)
            colors = colormap.diverging(colormap.normal_component_mm(offsets, renderer.normals(sequence)), 2.0)
            renderer.render(sequence[0], colors[0])
            times = []
            for f in range(frames):
                start = time.perf_counter()
                image = renderer.render(sequence[f], colors[f])
                times.append(time.perf_counter() - start)
            background = np.all(image == image[0, 0], axis=-1).mean()
            median = float(np.median(times))
            record({
                "case": f"render_{mesh}_{view}_{shading}_512",
                "points": len(points), "triangles": len(tris), "frames": frames,
                "fps": round(frames / sum(times), 2), "median_ms_per_frame": round(1e3 * median, 2),
                "covered_fraction": round(1.0 - float(background), 3),
                "target_fps": TARGET_FPS, "meets_target": frames / sum(times) >= TARGET_FPS,
            })
            if reference and view == "front" and shading == "smooth":
                start = time.perf_counter()
                looped = loop_reference(renderer, sequence[0].astype(np.float64), colors[0].astype(np.float64))
                ref_s = time.perf_counter() - start
                ours = renderer.render(sequence[0], colors[0]).astype(float) / 255.0
                drawn = looped.any(-1)
                record({
                    "case": f"render_{mesh}_front_smooth_512_reference_loop",
                    "fps": round(1.0 / ref_s, 3), "speedup_vectorized": round(ref_s / median, 1),
                    "max_abs_difference_on_drawn_pixels": round(float(np.abs(ours - looped)[drawn].max()), 4),
                })


def grid_layouts(topology: Topology, uv: np.ndarray) -> dict[str, UVs]:
    """The synthetic grid's uvs on one tile, and split down the middle over two."""
    corner_uv = uv[topology.face_vertex_indices]
    right_half = np.repeat(corner_uv[:, 0].reshape(-1, 4).mean(1) > 0.5, 4)
    corners = np.arange(len(corner_uv), dtype=np.int32)
    return {
        "one_tile": UVs(corner_uv.astype(np.float32), corners, "faceVarying"),
        "two_tiles": UVs((corner_uv + np.outer(right_half, [1.0, 0.0])).astype(np.float32), corners, "faceVarying"),
    }


def bench_uv(record: Recorder, mesh: str, points, topology, layouts: dict[str, UVs], resolution: int, frames: int) -> None:
    normals = Renderer(topology.triangles(), len(points), frame_camera(points)).normals(points)
    offsets = animated(points, normals, frames).astype(np.float32)
    for name, uvs in layouts.items():
        start = time.perf_counter()
        baker = UVBaker(topology, uvs, resolution)
        precompute = time.perf_counter() - start
        start = time.perf_counter()
        baker.bake(offsets)
        bake = (time.perf_counter() - start) / frames
        with tempfile.TemporaryDirectory() as folder:
            start = time.perf_counter()
            numbers = np.arange(1001, 1001 + frames)
            paths = write_offset_maps(folder, "offsets", baker, offsets, numbers, 96.0, __version__)
            write = (time.perf_counter() - start) / frames
        record({
            "case": f"uv_bake_{mesh}_{name}_{resolution}", "tiles": len(baker.tiles), "frames": frames,
            "precompute_s": round(precompute, 3), "bake_ms_per_frame": round(1e3 * bake, 2),
            "bake_and_write_half_exr_ms_per_frame": round(1e3 * write, 2), "files": len(paths),
        })


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--frames", type=int, default=40)
    arguments.add_argument("--uv-frames", type=int, default=8)
    arguments.add_argument("--resolution", type=int, default=1024)
    args = arguments.parse_args()
    with Recorder("bench_render", args) as record:
        record({
            "case": "machine", "cpus": os.cpu_count(), "python": platform.python_version(),
            "numpy": np.__version__, "facedyn": __version__,
        })
        points, quads, uv = synthetic_face()
        topology = Topology(np.full(len(quads), 4, np.int32), quads.ravel().astype(np.int32))
        bench_render(record, "grid", points, topology, args.frames, reference=True)
        bench_uv(record, "grid", points, topology, grid_layouts(topology, uv), args.resolution, args.uv_frames)
        head = default_face(43)
        bench_render(record, "default_face", head.neutral, head.topology, args.frames, reference=False)
        bench_uv(record, "default_face", head.neutral, head.topology, {"two_tiles": head.uvs}, args.resolution, args.uv_frames)


if __name__ == "__main__":
    main()
