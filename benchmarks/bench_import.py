"""`usdfacedyn import` in bounded memory: peak RSS on long USD mesh caches and an OBJ sequence.

Each source is the built-in 4,058-point face (facedyn.sim.default_face) with an expression
mode and a drift animated over the take, written the way a studio delivers it: a plain USD
mesh cache in metres, Z up (one .usdc with one points sample a frame, saved chunk by chunk
so the writer never holds it) or an OBJ file per frame. Then `usdfacedyn import` runs in its
own process (bench_long_take.run_step): its peak RSS is the process's VmHWM; throughput is
frames per second of its wall time. Cases: each --frames count as is, and resampled to
another rate with --fps (cubic, chunk by chunk); the OBJ sequence with a gap filled.

    python benchmarks/bench_import.py [--frames 10000 50000] [--obj-frames 3000] [--workdir DIR] [--keep] [--out FILE] [--note TEXT]

Prints one JSON object per case. Disk: about 0.05 MB per frame for the cache and as much
for the capture layer (50,000 frames: about 5 GB), 0.2 MB per OBJ file; removed
afterwards unless --keep.
"""
from __future__ import annotations

import functools
import shutil
from pathlib import Path

import numpy as np

from bench_long_take import run_step
from harness import Recorder, parser
from spill import work_folder, work_folder_arguments

SOURCE_FPS = 120.0
RESAMPLED_FPS = 100.0  # the --fps case: every output frame falls between source samples
CHUNK = 1000  # frames the source writers hold at a time


@functools.lru_cache(maxsize=1)
def built_in_face():
    from facedyn.sim.default_face import default_face

    return default_face()


def animated_face(frames: np.ndarray):
    """(points (F, N, 3) float32 in centimetres, Y up, topology) of the built-in face at frame indices `frames`."""
    face = built_in_face()
    t = np.asarray(frames, dtype=np.float64)[:, None, None] / SOURCE_FPS
    mode = face.identity_modes[0]
    drift = np.stack([np.sin(0.7 * t[..., 0]), 0.3 * np.sin(1.3 * t[..., 0]), np.zeros_like(t[..., 0])], axis=-1)
    return (face.neutral + np.sin(2.1 * t) * mode + 2.0 * drift).astype(np.float32), face.topology


def write_usd_cache(path: Path, count: int) -> Path:
    """A plain mesh cache (metres, Z up, no facedyn schema) of `count` frames, saved every CHUNK frames."""
    from pxr import Sdf, Usd, UsdGeom, Vt

    import facedyn.usd  # noqa: F401  (registers facedyn's plugins before any stage opens)

    layer = Sdf.Layer.CreateNew(str(path))
    stage = Usd.Stage.Open(layer)
    stage.SetTimeCodesPerSecond(SOURCE_FPS)
    stage.SetFramesPerSecond(SOURCE_FPS)
    UsdGeom.SetStageUpAxis(stage, "Z")
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    mesh = UsdGeom.Mesh.Define(stage, "/Capture/Face")
    _, topology = animated_face(np.zeros(1))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(topology.face_vertex_counts))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(topology.face_vertex_indices))
    attr = mesh.CreatePointsAttr().GetPath()
    for a in range(0, count, CHUNK):
        points, _ = animated_face(np.arange(a, min(count, a + CHUNK)))
        z_up_metres = np.stack([points[..., 0], -points[..., 2], points[..., 1]], axis=-1) / 100.0
        with Sdf.ChangeBlock():
            for k, frame in enumerate(z_up_metres):
                layer.SetTimeSample(attr, 1001.0 + a + k, Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(frame)))
        layer.Save()  # crate saves incrementally: the samples written so far leave memory
    return path


def write_obj_sequence(folder: Path, count: int, missing: range) -> Path:
    """`count` OBJ files face.1001.obj..., without the frames in `missing` (a gap import fills)."""
    from facedyn.io.obj import ObjMesh, write_obj

    folder.mkdir(parents=True)
    for a in range(0, count, CHUNK):
        frames = np.arange(a, min(count, a + CHUNK))
        points, topology = animated_face(frames)
        for frame, frame_points in zip(frames, points):
            if frame not in missing:
                write_obj(folder / f"face.{1001 + frame}.obj",
                          ObjMesh(frame_points, topology.face_vertex_counts, topology.face_vertex_indices))
    return folder


def import_case(name: str, source: Path, out: Path, frames: int, *flags) -> dict:
    take = out / name
    take.mkdir(parents=True)
    step = run_step("import", source, "-o", take / "capture.usdc", *flags)
    written = sum(p.stat().st_size for p in take.rglob("*") if p.is_file())
    shutil.rmtree(take)
    return {"case": name, "frames": frames, "points": 4058, "flags": " ".join(map(str, flags)), **step,
            "frames_per_second": round(frames / step["seconds"]), "layer_gb": round(written / 2**30, 2)}


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--frames", type=int, nargs="+", default=[10_000, 50_000])
    arguments.add_argument("--obj-frames", type=int, default=3000)
    work_folder_arguments(arguments)
    args = arguments.parse_args()
    with work_folder("bench_import.", args) as work, Recorder("bench_import", args) as record:
        for frames in args.frames:
            cache = write_usd_cache(work / f"cache_{frames}.usdc", frames)
            record(import_case(f"usd {frames}", cache, work, frames))
            resampled = int((frames - 1) * RESAMPLED_FPS / SOURCE_FPS) + 1
            record(import_case(f"usd {frames} resampled", cache, work, resampled, "--fps", RESAMPLED_FPS))
            if not args.keep:
                cache.unlink()
        if args.obj_frames:
            gap = range(args.obj_frames // 2, args.obj_frames // 2 + 5)
            folder = write_obj_sequence(work / "objs", args.obj_frames, gap)
            record(import_case(f"obj {args.obj_frames} (5 missing)", folder, work, args.obj_frames,
                               "--fps", SOURCE_FPS, "--units", 1.0))


if __name__ == "__main__":
    main()
