"""The import processor: any animated mesh (USD or an OBJ sequence) -> a canonical take.

The capture layer defines facedyn's layout (/Performance/Skull/Face), with the skull at the
identity and the tracked points baked to world space in centimetres, Y up; a `take.usda`
root beside it lists it as its base sublayer, ready for stabilize and the others.

A take's frames are consecutive whole frames at its rate (facedyn.usd.takechecks). A USD
capture that is not (samples between frames, gaps, a rate other than the model's) is
resampled with `--fps RATE`: points by cubic interpolation over time, frame numbers on the
new grid starting at the source's first frame. An OBJ sequence's --fps is its own rate, and
gaps in its frame numbers are filled the same way (the summary counts them).

The source streams into the layer CHUNK_FRAMES frames at a time (USD: one Get per frame,
facedyn.usd.source; OBJ: file by file, facedyn.io.obj.ObjFrames), each chunk resampled
from the samples it needs (facedyn.io.resample.CubicResampler), so memory does not grow
with the take; a take past 5,000 frames is written as value clips. Checks that need the
whole take (the time codes' grid, the frame range) run on the time codes before any point
is read; a fault found in a later chunk (a NaN, a changed topology) stops the write before
the layer or its take root exists.
"""
from __future__ import annotations

import glob
import itertools
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from facedyn.errors import UsageError
from facedyn.io.resample import CubicResampler, SplineWindow
from facedyn.performance import CAPTURED, TAKE_ROOT_FILE
from facedyn.processors.base import LayerOutput, Parameter, Plan, Processor, Reads, Request, Writes
from facedyn.progress import Progress

CHUNK_FRAMES = 1024  # frames read, resampled and written (one value clip of a long take) at a time
MAX_RESAMPLED_FRAMES = 10_000_000  # a day at 120 fps: a longer resampled grid is a wrong --fps or wrong time codes


class ImportProcessor(Processor):
    name = "import"
    version = "1"
    summary = "turn a time-sampled USD mesh or an OBJ sequence into a canonical take (capture layer + take.usda)"
    reads = Reads("sources", metavar="SRC", help="a USD file with an animated mesh, or OBJ files (a folder, a list or a quoted pattern)")
    writes = Writes("layer", role=CAPTURED, attach=False, help="the capture layer to write (.usdc); its take root is created beside it")
    parameters = (
        Parameter("mesh", str, "", "prim path of the animated Mesh in a USD source (default: the only one)"),
        Parameter("fps", float, 0.0, "OBJ: the sequence's frame rate (required); USD: resample the capture to this rate "
                  "onto whole frames (needed when its samples have gaps or fall between frames)", minimum=0.0, maximum=10000.0),
        Parameter("units", float, None, "centimetres per unit of an OBJ sequence (default: 1); a USD source states its own "
                  "metersPerUnit", above=0.0, maximum=1e6),
        Parameter("root", Path, None, "take root to create or extend (default: take.usda beside the output)", metavar="ROOT"),
        Parameter("actor", Path, None, "the actor asset (usdfacedyn actor) the take belongs to, recorded in the take root: "
                  "stabilize and the trainers then use it by default", metavar="ACTOR"),
    )

    def take_root(self, request: Request) -> Path:
        """The take root this import creates or extends."""
        root = request.params["root"]
        return Path(root) if root else request.output.parent / TAKE_ROOT_FILE

    def prepare(self, request: Request) -> Plan:
        from facedyn.io.obj import ObjFrames
        from facedyn.usd.source import open_mesh_source

        source = _source(request)
        root = self.take_root(request)
        _check_flags_apply(source, request.params)
        if source.kind == "usd":
            resample = request.params["fps"] > 0
            mesh = open_mesh_source(source.paths[0], request.params["mesh"], request.frames, whole_frames=not resample)
            description = {"source": str(source.paths[0]), "mesh": str(mesh.prim.GetPath()), "frames": len(mesh.time_codes),
                           "fps": mesh.timing.time_codes_per_second, "root": str(root)}
            if resample:
                description["resample_fps"] = request.params["fps"]
            return Plan(description, (source, request, root, _usd_capture(source.paths[0], mesh, request.params["fps"])))
        fps = _require_fps(request)
        paths, frames = _obj_frames(source.paths, request.frames)
        description = {"source": f"{len(source.paths)} OBJ files", "fps": fps, "root": str(root)}
        return Plan(description, (source, request, root, _obj_capture(paths, frames, ObjFrames(paths), request.params)))

    def run(self, plan: Plan, progress: Progress) -> LayerOutput:
        source, request, root, capture = plan.state
        output = capture.output(progress)
        output.root = root
        if request.params["actor"] is not None:
            from facedyn.usd.actor_asset import read_actor_for

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


def _check_flags_apply(source: _Source, params: dict) -> None:
    """A flag this kind of source cannot honour is a usage error, not silently ignored."""
    if source.kind == "usd" and params["units"] is not None:
        raise UsageError(f"--units applies to OBJ sequences; {source.paths[0]} is USD, whose own metersPerUnit "
                         "is what import converts from (fix that metadata instead)")
    if source.kind == "obj" and params["mesh"]:
        raise UsageError("--mesh picks a prim in a USD source; an OBJ sequence holds one mesh")


def _require_fps(request: Request) -> float:
    fps = request.params["fps"]
    if fps <= 0:
        raise UsageError("an OBJ sequence needs --fps (its frame rate), e.g. --fps 120")
    return fps


@dataclass
class _Capture:
    """A capture ready to stream into its layer: the output frames, how to read the source's samples, what the layer says once."""

    frames: np.ndarray  # (F,) the layer's frame numbers
    read: Callable[[int, int], np.ndarray]  # source samples lo..hi-1 -> (hi - lo, N, 3) float32 canonical points
    resampler: CubicResampler | None  # None: the samples are the frames
    layer: object  # facedyn.usd.layers.LayerContent: the static values (topology, uvs, face, skull)
    timing: object  # facedyn.usd.timing.Timing of the take
    inputs: list[str]
    summary: dict

    def output(self, progress: Progress) -> LayerOutput:
        """The layer, its first chunk read now: before the runner locks the take root, so a fault there leaves no file at all."""
        chunks = self.chunks(progress)
        first = next(chunks)
        return LayerOutput(layer=self.layer, timing=self.timing, inputs=self.inputs, define=True, summary=self.summary,
                           chunks=itertools.chain([first], chunks))

    def chunks(self, progress: Progress):
        """The layer's points CHUNK_FRAMES frames at a time, each from the source samples it needs (read as it is written)."""
        from facedyn.usd.layers import LayerContent

        count = len(self.frames)
        if self.resampler is None:  # each chunk is its own samples
            windows = (SplineWindow(a, b, a, b) for a in range(0, count, CHUNK_FRAMES) for b in [min(a + CHUNK_FRAMES, count)])
        else:
            windows = self.resampler.windows(CHUNK_FRAMES)
        for window in windows:
            points = self.read(window.lo, window.hi)
            if self.resampler is not None:
                points = self.resampler.resample(window, points)
            if window.start == 0:  # started once the first chunk reads: a fault in a short take is one line
                progress.start("import", count)
            yield LayerContent(frames=self.frames[window.start:window.stop], points=points)
            progress.advance(window.stop - window.start)
        progress.finish()


def _usd_capture(path: Path, mesh, rate: float) -> _Capture:
    """A USD mesh (facedyn.usd.source.MeshSource) as a take at its own rate, or resampled to `rate` (> 0)."""
    from facedyn.usd.takechecks import frame_grid_problem

    mesh.face.role = CAPTURED
    tcps, fps = mesh.timing.time_codes_per_second, mesh.timing.frames_per_second
    codes = frames = mesh.time_codes
    summary = {"source_mesh": str(mesh.prim.GetPath()), "points": mesh.point_count, "fps": tcps}
    resampler = None
    if rate > 0 and not (rate == tcps and frame_grid_problem(codes, tcps) is None):
        resampler = _resampler(codes / tcps, rate, str(path))
        frames = round(float(codes[0])) + np.arange(resampler.count, dtype=np.float64)
        summary.update(fps=rate, source_fps=tcps, source_frames=len(codes))
        tcps = fps = rate
    layer, timing = _capture_layer(frames, tcps, fps, mesh.topology, mesh.uvs, mesh.face)
    return _Capture(frames, lambda lo, hi: mesh.read(codes[lo:hi]), resampler, layer, timing, [str(path)], summary)


def _obj_frames(paths: list[Path], frame_range: tuple[float, float] | None) -> tuple[list[Path], np.ndarray]:
    """The OBJ files to import (those in --frames) and their frame numbers."""
    frames = _frame_numbers(paths)
    if frame_range is not None:
        keep = (frames >= frame_range[0]) & (frames <= frame_range[1])
        if not keep.any():
            raise UsageError(f"no OBJ frame in {frame_range[0]:g}:{frame_range[1]:g}")
        paths, frames = [p for p, k in zip(paths, keep) if k], frames[keep]
    return paths, frames


def _obj_capture(paths: list[Path], frames: np.ndarray, sequence, params: dict) -> _Capture:
    """An OBJ sequence (facedyn.io.obj.ObjFrames) at --fps, scaled by --units, gaps in its frame numbers filled."""
    from facedyn.performance import Topology
    from facedyn.usd import schema
    from facedyn.usd.takechecks import frame_grid_problem

    fps, units = params["fps"], 1.0 if params["units"] is None else params["units"]
    resampler, filled = None, frames
    if frame_grid_problem(frames, fps) is not None:  # gaps in the frame numbers
        resampler = _resampler(frames / fps, fps, str(paths[0].parent))
        filled = frames[0] + np.arange(resampler.count, dtype=np.float64)
    first = sequence.first
    layer, timing = _capture_layer(filled, fps, fps, Topology(first.face_vertex_counts, first.face_vertex_indices), sequence.uvs,
                                   schema.FaceAttributes(role=CAPTURED))
    summary = {"obj_files": len(paths), "points": len(first.points), "fps": fps, "filled_frames": len(filled) - len(frames)}
    return _Capture(filled, lambda lo, hi: (sequence.read(lo, hi) * units).astype(np.float32), resampler, layer, timing,
                    [str(p) for p in paths], summary)


def _capture_layer(frames: np.ndarray, time_codes_per_second: float, fps: float, topology, uvs, face):
    """The capture layer's static values (its mesh defined, the skull at the identity) and the take's timing."""
    from facedyn.usd import schema
    from facedyn.usd.layers import LayerContent
    from facedyn.usd.takechecks import CENTIMETRES
    from facedyn.usd.timing import Timing

    layer = LayerContent(frames=frames, topology=topology, uvs=uvs, face=face, skull=schema.SkullAttributes(solver="identity"))
    return layer, Timing(time_codes_per_second, fps, float(frames[0]), float(frames[-1]), CENTIMETRES, "Y")


def _resampler(seconds: np.ndarray, rate: float, source: str) -> CubicResampler:
    """The cubic resampler onto whole frames at `rate`; a grid of more than MAX_RESAMPLED_FRAMES is refused before anything is read."""
    from facedyn.usd.errors import TakeError

    span = (seconds[-1] - seconds[0]) * rate
    if not span < MAX_RESAMPLED_FRAMES:
        raise TakeError(f"{source}: resampled to {rate:g} fps the capture would hold {span + 1:.0f} frames (more than "
                        f"{MAX_RESAMPLED_FRAMES:,}); check --fps, or import a shorter range with --frames")
    return CubicResampler(seconds, rate)


def _frame_number_key(path: Path):
    match = re.search(r"(\d+)$", path.stem)
    return (0, int(match.group(1)), path.name) if match else (1, 0, path.name)


def _frame_numbers(paths: list[Path]) -> np.ndarray:
    """The trailing frame numbers of the file names (face.1001.obj -> 1001), else 1, 2, 3..."""
    numbers = [re.search(r"(\d+)$", p.stem) for p in paths]
    if all(numbers) and len({int(m.group(1)) for m in numbers}) == len(paths):
        return np.array([int(m.group(1)) for m in numbers], dtype=np.float64)
    return np.arange(1, len(paths) + 1, dtype=np.float64)
