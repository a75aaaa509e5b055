"""The import processor: any animated mesh (USD or an OBJ sequence) -> a canonical take.

The capture layer defines facedyn's layout (/Performance/Skull/Face), with the skull at the
identity and the tracked points baked to world space in centimetres, Y up; a `take.usda`
root beside it lists it as its base sublayer, ready for stabilize and the others.

A take's frames are consecutive whole frames at its rate (facedyn.usd.takechecks). A USD
capture that is not (samples between frames, gaps, a rate other than the model's) is
resampled with `--fps RATE`: points by cubic interpolation over time, frame numbers on the
new grid starting at the source's first frame. An OBJ sequence's --fps is its own rate, and
gaps in its frame numbers are filled the same way (the summary counts them).
"""
from __future__ import annotations

import glob
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from facedyn.errors import UsageError
from facedyn.processors.base import LayerOutput, Parameter, Plan, Processor, Reads, Request, Writes
from facedyn.progress import Progress

MAX_RESAMPLED_BYTES = 8 << 30  # a resampled capture larger than this is refused before it is allocated


class ImportProcessor(Processor):
    name = "import"
    version = "1"
    summary = "turn a time-sampled USD mesh or an OBJ sequence into a canonical take (capture layer + take.usda)"
    reads = Reads("sources", metavar="SRC", help="a USD file with an animated mesh, or OBJ files (a folder, a list or a quoted pattern)")
    writes = Writes("layer", role="captured", help="the capture layer to write (.usdc); its take root is created beside it")
    parameters = (
        Parameter("mesh", str, "", "prim path of the animated Mesh in a USD source (default: the only one)"),
        Parameter("fps", float, 0.0, "OBJ: the sequence's frame rate (required); USD: resample the capture to this rate "
                  "onto whole frames (needed when its samples have gaps or fall between frames)", minimum=0.0, maximum=10000.0),
        Parameter("units", float, 1.0, "centimetres per unit of an OBJ sequence", above=0.0, maximum=1e6),
        Parameter("root", Path, None, "take root to create or extend (default: take.usda beside the output)", metavar="ROOT"),
        Parameter("actor", Path, None, "the actor asset (usdfacedyn actor) the take belongs to, recorded in the take root: "
                  "stabilize and the trainers then use it by default", metavar="ACTOR"),
    )

    def take_root(self, request: Request) -> Path:
        """The take root this import creates or extends."""
        root = request.params["root"]
        return Path(root) if root else request.output.parent / "take.usda"

    def prepare(self, request: Request) -> Plan:
        if request.attach is not None:
            raise UsageError("import creates or extends its own take root; name it with --root, not --attach")
        source = _source(request)
        root = self.take_root(request)
        if source.kind == "usd":
            resample = request.params["fps"] > 0
            stage, mesh_prim, time_codes = _usd_source(source.paths[0], request.params["mesh"], request.frames, whole_frames=not resample)
            description = {"source": str(source.paths[0]), "mesh": str(mesh_prim.GetPath()), "frames": len(time_codes),
                           "fps": stage.GetTimeCodesPerSecond(), "root": str(root)}
            if resample:
                description["resample_fps"] = request.params["fps"]
            return Plan(description, (source, request, root, (stage, mesh_prim, time_codes)))
        _require_fps(request)
        description = {"source": f"{len(source.paths)} OBJ files", "fps": request.params["fps"], "root": str(root)}
        return Plan(description, (source, request, root, None))

    def run(self, plan: Plan, progress: Progress) -> LayerOutput:
        source, request, root, usd = plan.state
        output = _import_usd(source.paths[0], usd, request, progress) if source.kind == "usd" else _import_obj(source.paths, request, progress)
        output.root = root
        if request.params["actor"] is not None:
            from facedyn.usd.actor import read_actor_for

            read_actor_for(request.params["actor"], output.layer.topology, source.paths[0])
            output.actor = request.params["actor"]
        return output


class _Source:
    def __init__(self, kind: str, paths: list[Path]):
        self.kind, self.paths = kind, paths


def _source(request: Request) -> _Source:
    paths = list(request.inputs)
    if len(paths) == 1 and not paths[0].exists() and glob.has_magic(str(paths[0])):  # a quoted pattern
        paths = [Path(p) for p in glob.glob(str(paths[0]))]
        if not paths:
            raise UsageError(f"{request.inputs[0]}: the pattern matches no file")
    if len(paths) == 1 and paths[0].is_dir():
        paths = sorted(paths[0].glob("*.obj"))
        if not paths:
            raise UsageError(f"{request.inputs[0]}: folder holds no .obj files")
    suffixes = {p.suffix.lower() for p in paths}
    if suffixes == {".obj"}:
        return _Source("obj", sorted(paths, key=_frame_number_key))
    if len(paths) == 1:
        return _Source("usd", paths)
    raise UsageError("import takes one USD file, or OBJ files (a folder, or a list such as face.*.obj)")


def _require_fps(request: Request) -> float:
    fps = request.params["fps"]
    if fps <= 0:
        raise UsageError("an OBJ sequence needs --fps (its frame rate), e.g. --fps 120")
    return fps


@dataclass
class CanonicalMesh:
    """An animated (or static) USD mesh in world space, centimetres, Y up: what a take holds."""

    points: np.ndarray  # (F, N, 3) float32
    frames: np.ndarray  # (F,) time codes
    fps: float
    topology: object  # facedyn.performance.Topology
    uvs: object  # facedyn.performance.UVs | None
    prim_path: str
    face: object  # facedyn.usd.schema.FaceAttributes authored on the source mesh
    source_fps: tuple[float, float]  # the source stage's (timeCodesPerSecond, framesPerSecond)


def _usd_source(path: Path, mesh: str, frames=None, static_ok: bool = False, whole_frames: bool = True):
    """(stage, the mesh prim, its time codes): the named mesh, else the only animated one.

    A UsdSkel animation is baked first (in memory), so a skinned or blend-shape rig's mesh
    counts as animated. `whole_frames`: the time codes must be consecutive whole frames
    (see select_time_codes).
    """
    from facedyn.usd.errors import TakeError
    from facedyn.usd.skel import bake_skel_animations
    from facedyn.usd.stage import get_prim, layer_name, open_stage
    from facedyn.usd.take import find_animated_meshes, select_time_codes
    from pxr import UsdGeom

    stage = open_stage(path)
    bake_skel_animations(stage)
    if mesh:
        mesh_prim = get_prim(stage, mesh)
        if not mesh_prim.IsA(UsdGeom.Mesh):
            raise TakeError(f"{layer_name(stage)}: {mesh_prim.GetPath()} is not a Mesh")
    else:
        animated = find_animated_meshes(stage)
        if static_ok and not animated:
            animated = [prim for prim in stage.Traverse() if prim.IsA(UsdGeom.Mesh)]
        if not animated:
            raise TakeError(f"{layer_name(stage)}: no Mesh with time-sampled points (nothing to import)")
        if len(animated) > 1:
            names = ", ".join(str(p.GetPath()) for p in animated)
            raise TakeError(f"{layer_name(stage)}: several {'animated ' if not static_ok else ''}meshes ({names}); choose one with --mesh")
        mesh_prim = animated[0]
    if static_ok and UsdGeom.Mesh(mesh_prim).GetPointsAttr().GetNumTimeSamples() == 0:
        return stage, mesh_prim, None
    return stage, mesh_prim, select_time_codes(stage, mesh_prim, frames, whole_frames)


def read_usd_mesh(path: Path, mesh: str = "", frames=None, first_frame_only: bool = False, usd=None) -> CanonicalMesh:
    """A USD mesh's points in world space, centimetres, Y up (every frame, or the first only)."""
    from facedyn.usd import schema
    from facedyn.usd.errors import TakeError
    from facedyn.usd.stage import layer_name
    from facedyn.usd.take import ensure_plausible_points, read_topology, read_uvs, read_vec3_samples
    from facedyn.usd.takechecks import CENTIMETRES
    from facedyn.usd.timing import Timing
    from pxr import Usd, UsdGeom

    stage, mesh_prim, time_codes = usd or _usd_source(path, mesh, frames, static_ok=first_frame_only)
    where = f"{layer_name(stage)}: {mesh_prim.GetPath()}"
    geom = UsdGeom.Mesh(mesh_prim)
    topology = read_topology(geom, where)
    if time_codes is None:  # a static mesh: its default value
        value = geom.GetPointsAttr().Get()
        if value is None:
            raise TakeError(f"{where}.points has no value")
        time_codes, codes = np.zeros(1), [Usd.TimeCode.Default()]
        points = np.asarray(value, dtype=np.float64)[None]
    else:
        time_codes = time_codes[:1] if first_frame_only else time_codes
        codes = [Usd.TimeCode(float(t)) for t in time_codes]
        points = read_vec3_samples(geom.GetPointsAttr(), time_codes, where + ".points").astype(np.float64)
    ensure_plausible_points(points, time_codes, where + ".points")
    if points.shape[1] != topology.point_count:
        raise TakeError(f"{where}: {points.shape[1]} points but the topology indexes {topology.point_count}")
    xforms = np.array([np.asarray(UsdGeom.XformCache(code).GetLocalToWorldTransform(mesh_prim)) for code in codes])
    if not np.allclose(xforms, np.eye(4)):
        points = np.einsum("fni,fij->fnj", points, xforms[:, :3, :3]) + xforms[:, None, 3, :3]
    timing = Timing.from_stage(stage)
    points = _to_canonical_axes(points * (timing.meters_per_unit / CENTIMETRES), timing.up_axis)
    return CanonicalMesh(points.astype(np.float32), time_codes, timing.time_codes_per_second, topology, read_uvs(geom),
                         str(mesh_prim.GetPath()), schema.FaceAttributes.read(mesh_prim),
                         (timing.time_codes_per_second, timing.frames_per_second))


def _import_usd(path: Path, usd, request: Request, progress: Progress) -> LayerOutput:
    from facedyn.usd import schema
    from facedyn.usd.layers import LayerContent
    from facedyn.usd.takechecks import CENTIMETRES, frame_grid_problem
    from facedyn.usd.timing import Timing

    mesh = read_usd_mesh(path, usd=usd)
    face = mesh.face
    face.role = "captured"
    tcps, fps = mesh.source_fps
    frames, points = mesh.frames, mesh.points
    summary = {"source_mesh": mesh.prim_path, "points": mesh.points.shape[1], "fps": tcps}
    rate = request.params["fps"]
    if rate > 0 and not (rate == tcps and frame_grid_problem(frames, tcps) is None):
        frames, points = resample(points, frames / tcps, rate, round(float(frames[0])), str(path))
        tcps = fps = rate
        summary.update(fps=rate, source_fps=mesh.source_fps[0], source_frames=len(mesh.frames))
    layer = LayerContent(frames=frames, points=points, topology=mesh.topology, uvs=mesh.uvs, face=face,
                         skull=schema.SkullAttributes(solver="identity"))
    out_timing = Timing(tcps, fps, float(frames[0]), float(frames[-1]), CENTIMETRES, "Y")
    return LayerOutput(layer=layer, timing=out_timing, inputs=[str(path)], define=True, summary=summary)


def _import_obj(paths: list[Path], request: Request, progress: Progress) -> LayerOutput:
    from facedyn.io.obj import read_obj_sequence
    from facedyn.performance import Topology
    from facedyn.usd import schema
    from facedyn.usd.layers import LayerContent
    from facedyn.usd.takechecks import CENTIMETRES, frame_grid_problem
    from facedyn.usd.timing import Timing

    fps = _require_fps(request)
    frames = _frame_numbers(paths)
    if request.frames is not None:
        keep = (frames >= request.frames[0]) & (frames <= request.frames[1])
        if not keep.any():
            raise UsageError(f"no OBJ frame in {request.frames[0]:g}:{request.frames[1]:g}")
        paths, frames = [p for p, k in zip(paths, keep) if k], frames[keep]
    sequence = read_obj_sequence(paths, progress=progress)
    points = (sequence.points * request.params["units"]).astype(np.float32)
    read_frames = len(frames)
    if frame_grid_problem(frames, fps) is not None:  # gaps in the frame numbers
        frames, points = resample(points, frames / fps, fps, frames[0], str(paths[0].parent))
    layer = LayerContent(
        frames=frames,
        points=points,
        topology=Topology(sequence.face_vertex_counts, sequence.face_vertex_indices),
        uvs=sequence.uvs,
        face=schema.FaceAttributes(role="captured"),
        skull=schema.SkullAttributes(solver="identity"),
    )
    timing = Timing(fps, fps, float(frames[0]), float(frames[-1]), CENTIMETRES, "Y")
    summary = {"obj_files": len(paths), "points": points.shape[1], "fps": fps, "filled_frames": len(frames) - read_frames}
    return LayerOutput(layer=layer, timing=timing, inputs=[str(p) for p in paths], define=True, summary=summary)


def resample(points: np.ndarray, seconds: np.ndarray, rate: float, first_frame: float, source: str) -> tuple[np.ndarray, np.ndarray]:
    """(frames, points) on whole frames first_frame, first_frame + 1, ... every 1/rate s from the first sample.

    points (F, N, 3) sampled at increasing `seconds` are interpolated over time by a cubic
    spline (not-a-knot ends; quadratic or linear when there are only 3 or 2 samples), which
    reproduces motion that is a cubic polynomial in time exactly; samples already on the
    grid come back unchanged up to float32 rounding. `source` names the input in errors.
    """
    from scipy.interpolate import make_interp_spline

    from facedyn.usd.errors import TakeError

    count = int(np.floor((seconds[-1] - seconds[0]) * rate + 1e-6)) + 1
    size = count * points.shape[1] * 3 * 4
    if size > MAX_RESAMPLED_BYTES:
        raise TakeError(f"{source}: resampled to {rate:g} fps the capture would hold {count} frames ({size / 2**30:.1f} GiB); "
                        f"import a shorter range with --frames")
    frames = first_frame + np.arange(count, dtype=np.float64)
    if len(seconds) == 1:
        return frames, points.astype(np.float32)
    spline = make_interp_spline(seconds, points.astype(np.float64), k=min(3, len(seconds) - 1), axis=0)
    grid = seconds[0] + np.arange(count, dtype=np.float64) / rate
    return frames, spline(np.minimum(grid, seconds[-1])).astype(np.float32)


def _frame_number_key(path: Path):
    match = re.search(r"(\d+)$", path.stem)
    return (0, int(match.group(1)), path.name) if match else (1, 0, path.name)


def _frame_numbers(paths: list[Path]) -> np.ndarray:
    """The trailing frame numbers of the file names (face.1001.obj -> 1001), else 1, 2, 3..."""
    numbers = [re.search(r"(\d+)$", p.stem) for p in paths]
    if all(numbers) and len({int(m.group(1)) for m in numbers}) == len(paths):
        return np.array([int(m.group(1)) for m in numbers], dtype=np.float64)
    return np.arange(1, len(paths) + 1, dtype=np.float64)


def _to_canonical_axes(points: np.ndarray, up_axis: str) -> np.ndarray:
    """Z-up scenes are turned Y-up (x, y, z) -> (x, z, -y); Y-up ones are left alone."""
    if up_axis == "Z":
        return np.stack([points[..., 0], points[..., 2], -points[..., 1]], axis=-1)
    return points
