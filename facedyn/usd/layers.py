"""Writing result layers and take roots, atomically.

A processor's result is a `LayerContent` of arrays; `write_layer` turns it into one USD
layer (`def`s for an imported capture, `over`s for everything built on top of it), copies
the input's timing, authors every covered frame, records provenance, and writes the file to
a temporary name in the destination folder before renaming it into place, so a failed or
interrupted run never leaves a damaged file behind.
"""
from __future__ import annotations

import itertools
import os
import shutil
import tempfile
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np
from pxr import Gf, Kind, Sdf, Tf, Usd, UsdGeom, Vt

from facedyn.performance import UVs, Topology, roles
from facedyn.usd import clips, schema
from facedyn.usd.errors import TakeError
from facedyn.usd.layerstack import LEGACY_PROCESSOR_ROLES, TAKE_ROOT
from facedyn.usd.stage import relative_asset_path
from facedyn.usd.timing import Timing

PERFORMANCE_PATH = "/Performance"
SKULL_PATH = "/Performance/Skull"
FACE_PATH = "/Performance/Skull/Face"
PER_FRAME = ("points", "skull_translate", "skull_orient", "offsets", "solve_error", "display_color")


@dataclass
class LayerContent:
    """What one layer says about a take, as arrays (None = this layer has no opinion)."""

    frames: np.ndarray  # (F,) time codes
    mesh_path: str = FACE_PATH
    skull_path: str = SKULL_PATH
    points: np.ndarray | None = None  # (F, N, 3) skull space
    skull_translate: np.ndarray | None = None  # (F, 3)
    skull_orient: np.ndarray | None = None  # (F, 4) w, x, y, z
    offsets: np.ndarray | None = None  # (F, N, 3)
    solve_error: np.ndarray | None = None  # (F,)
    face: schema.FaceAttributes = field(default_factory=schema.FaceAttributes)
    skull: schema.SkullAttributes | None = None
    topology: Topology | None = None  # only when the layer defines the mesh
    uvs: UVs | None = None
    display_color: np.ndarray | None = None  # (F, N, 3) heat-map colours for viewers


def write_layer(
    path: str | os.PathLike,
    content: LayerContent,
    timing: Timing,
    provenance: schema.Provenance,
    define: bool = False,
    chunks: Iterable[LayerContent] | None = None,
    clip_threshold: int | None = None,
) -> Path:
    """Write `content` as a layer at `path` (atomically) and return the path.

    The layer records its run (schema.RunRecord): processor, role, parameters, frames and
    inputs relative to `path`, each with its run id, so the same inputs give the same bytes.
    `chunks` streams the per-frame values (consecutive LayerContents over content.frames,
    e.g. a generator computing them) instead of content's own arrays; a layer of more than
    `clip_threshold` (default clips.CLIP_THRESHOLD) frames is then written as value clips, one per chunk (facedyn.usd.clips),
    so it is never whole in memory.
    """
    path = Path(path)
    check_writable(path)
    sweep_stale_temps(path)
    pieces = iter([content] if chunks is None else chunks)
    first = next(pieces, None)
    if first is None:
        raise TakeError("nothing to write: the layer covers no frames")
    _check_shapes(content, per_frame=False)  # the arrays are checked chunk by chunk (_checked)
    record = provenance.record(path.parent, _layer_role(provenance, content))
    layer = Sdf.Layer.CreateAnonymous(path.suffix)
    frames = np.asarray(content.frames, dtype=np.float64)
    timing.with_frames(float(frames[0]), float(frames[-1])).apply(layer)
    layer.customLayerData = {"facedyn": record.as_dict()}
    stage = Usd.Stage.Open(layer)
    layer.defaultPrim = Sdf.Path(content.skull_path).GetPrefixes()[0].name
    declared = replace(content, **{name: getattr(first, name) for name in PER_FRAME})  # which attributes vary
    mesh_prim, skull_prim = _author_prims(stage, declared, define)
    _author_static(mesh_prim, skull_prim, declared, record)
    mesh_path, skull_path = mesh_prim.GetPath(), skull_prim.GetPath() if skull_prim else None
    pieces = _checked(itertools.chain([first], pieces), len(frames))
    if len(frames) <= (clips.CLIP_THRESHOLD if clip_threshold is None else clip_threshold):
        for piece in pieces:
            _author_time_samples(layer, mesh_path, skull_path, piece)
        export_atomically(layer, path)
        clips.remove_other_clips(path, keep=None)
        return path
    varying = [attr for attr, _, _ in _frame_values(mesh_path, skull_path, first)]
    writer = clips.ClipWriter(path, record.run, layer, skull_path or mesh_path.GetParentPath(), varying, export_atomically)
    try:
        for piece in pieces:
            clip = writer.new_clip()
            _author_time_samples(clip, mesh_path, skull_path, piece)
            writer.add(clip, float(piece.frames[0]), float(piece.frames[-1]))
            del clip
        writer.finish()
        export_atomically(layer, path)
    finally:
        writer.discard()
    clips.remove_other_clips(path, keep=writer.folder)
    return path


def _checked(pieces: Iterator[LayerContent], total: int) -> Iterator[LayerContent]:
    """Each chunk's shapes checked as it comes; together they must cover the layer's frames."""
    count = 0
    for piece in pieces:
        _check_shapes(piece)
        count += len(piece.frames)
        yield piece
    if count != total:
        raise ValueError(f"the chunks cover {count} frames, the layer {total}")


def _author_prims(stage: Usd.Stage, content: LayerContent, define: bool):
    skull_path, mesh_path = Sdf.Path(content.skull_path), Sdf.Path(content.mesh_path)
    if define:
        root = UsdGeom.Xform.Define(stage, skull_path.GetPrefixes()[0]).GetPrim()
        Usd.ModelAPI(root).SetKind(Kind.Tokens.component)
        skull_prim = UsdGeom.Xform.Define(stage, skull_path).GetPrim()
        mesh_prim = UsdGeom.Mesh.Define(stage, mesh_path).GetPrim()
    else:
        skull_prim = stage.OverridePrim(skull_path)
        mesh_prim = stage.OverridePrim(mesh_path)
    return mesh_prim, skull_prim


def _author_static(mesh_prim: Usd.Prim, skull_prim: Usd.Prim, content: LayerContent, record: schema.RunRecord) -> None:
    types = Sdf.ValueTypeNames
    has_skull_motion = content.skull_translate is not None or content.skull_orient is not None
    if content.skull is not None or has_skull_motion:
        (content.skull or schema.SkullAttributes()).write(skull_prim)
    if has_skull_motion or content.skull is not None:
        skull_prim.CreateAttribute("xformOp:translate", types.Double3, custom=False)
        skull_prim.CreateAttribute("xformOp:orient", types.Quatd, custom=False)
        skull_prim.CreateAttribute("xformOpOrder", types.TokenArray, custom=False).Set(
            Vt.TokenArray(["xformOp:translate", "xformOp:orient"])
        )
        if not has_skull_motion:  # a static identity skull, e.g. an imported capture
            skull_prim.GetAttribute("xformOp:translate").Set(Gf.Vec3d(0, 0, 0))
            skull_prim.GetAttribute("xformOp:orient").Set(Gf.Quatd(1, 0, 0, 0))
    if content.solve_error is not None:
        skull_prim.CreateAttribute(schema.SOLVE_ERROR_ATTR, types.Float)
    content.face.write(mesh_prim)
    if content.topology is not None:
        mesh = UsdGeom.Mesh(mesh_prim)
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(content.topology.face_vertex_counts, np.int32)))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(content.topology.face_vertex_indices, np.int32)))
        mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    if content.uvs is not None:
        primvar = UsdGeom.PrimvarsAPI(mesh_prim).CreatePrimvar("st", types.TexCoord2fArray, content.uvs.interpolation)
        primvar.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(content.uvs.values, np.float32)))
        if content.uvs.indices is not None:
            primvar.SetIndices(Vt.IntArray.FromNumpy(np.ascontiguousarray(content.uvs.indices, np.int32)))
    if content.points is not None:
        mesh_prim.CreateAttribute("points", types.Point3fArray, custom=False)
        mesh_prim.CreateAttribute("extent", types.Float3Array, custom=False)
    if content.offsets is not None:
        UsdGeom.PrimvarsAPI(mesh_prim).CreatePrimvar(
            schema.OFFSETS_ATTR.removeprefix("primvars:"), types.Vector3fArray, UsdGeom.Tokens.vertex
        )
    if content.display_color is not None:
        UsdGeom.PrimvarsAPI(mesh_prim).CreatePrimvar("displayColor", types.Color3fArray, UsdGeom.Tokens.vertex)
    record.write(mesh_prim)


def _layer_role(provenance: schema.Provenance, content: LayerContent) -> str:
    """The role a layer records: the provenance's, else its processor's (older callers), else its face's."""
    name = provenance.role or LEGACY_PROCESSOR_ROLES.get(provenance.processor) or content.face.role
    if name not in roles():
        raise TakeError(f"{provenance.processor}: cannot write a layer of role {name!r}; known roles: {', '.join(roles())}")
    return name


def _author_time_samples(layer: Sdf.Layer, mesh_path: Sdf.Path, skull_path: Sdf.Path | None, content: LayerContent) -> None:
    """Author every frame's values directly on the layer (fast: no stage notices per sample)."""
    frames = [float(f) for f in content.frames]
    with Sdf.ChangeBlock():
        for attr_path, convert, values in _frame_values(mesh_path, skull_path, content):
            for frame, value in zip(frames, values):
                layer.SetTimeSample(attr_path, frame, convert(value) if convert else value)


def _frame_values(mesh_path: Sdf.Path, skull_path: Sdf.Path | None, content: LayerContent) -> list:
    """(attribute path, conversion to a USD value, per-frame values) of every time-varying attribute content has."""
    per_frame = []
    if content.points is not None:
        points = np.ascontiguousarray(content.points, dtype=np.float32)
        extent = frame_extents(points)
        per_frame.append((mesh_path.AppendProperty("points"), Vt.Vec3fArray.FromNumpy, points))
        per_frame.append((mesh_path.AppendProperty("extent"), Vt.Vec3fArray.FromNumpy, extent))
    if content.offsets is not None:
        per_frame.append((mesh_path.AppendProperty(schema.OFFSETS_ATTR), Vt.Vec3fArray.FromNumpy, np.ascontiguousarray(content.offsets, np.float32)))
    if content.display_color is not None:
        per_frame.append((mesh_path.AppendProperty("primvars:displayColor"), Vt.Vec3fArray.FromNumpy, np.ascontiguousarray(content.display_color, np.float32)))
    if skull_path is not None and content.skull_translate is not None:
        per_frame.append((skull_path.AppendProperty("xformOp:translate"), Gf.Vec3d, np.asarray(content.skull_translate, np.float64).tolist()))
    if skull_path is not None and content.skull_orient is not None:
        quats = [Gf.Quatd(w, x, y, z) for w, x, y, z in np.asarray(content.skull_orient, np.float64).tolist()]
        per_frame.append((skull_path.AppendProperty("xformOp:orient"), None, quats))
    if skull_path is not None and content.solve_error is not None:
        per_frame.append((skull_path.AppendProperty(schema.SOLVE_ERROR_ATTR), float, np.asarray(content.solve_error, np.float64).tolist()))
    return per_frame


def frame_extents(points: np.ndarray) -> np.ndarray:
    """(F, 2, 3) per-frame bounds; reduced one coordinate at a time (contiguous, ~15x faster)."""
    lows = [points[..., k].min(axis=1) for k in range(3)]
    highs = [points[..., k].max(axis=1) for k in range(3)]
    return np.stack([np.stack(lows, axis=1), np.stack(highs, axis=1)], axis=1)


def _check_shapes(content: LayerContent, per_frame: bool = True) -> None:
    f = len(content.frames)
    if f == 0:
        raise TakeError("nothing to write: the layer covers no frames")
    for name in PER_FRAME if per_frame else ():
        value = getattr(content, name)
        if value is not None and len(value) != f:
            raise ValueError(f"{name} has {len(value)} frames, the layer covers {f}")
        if value is not None and not np.isfinite(value).all():
            raise TakeError(f"refusing to write non-finite {name} for {content.mesh_path}")


def check_writable(path: Path) -> None:
    """Fail early (before any work) when path's folder is missing or not writable."""
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise TakeError(f"{path}: output folder {folder} does not exist")
    try:  # a real probe: permission bits do not tell the whole story (root, read-only mounts)
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError:
        raise TakeError(f"{path}: output folder {folder} is not writable") from None
    if path.is_dir():
        raise TakeError(f"{path}: is a folder, expected a file name")
    if not Sdf.FileFormat.FindByExtension(path.suffix.lstrip(".")):
        raise TakeError(f"{path}: not a USD file name (use .usdc for data layers, .usda for shot layers)")


def export_atomically(layer: Sdf.Layer, path: Path) -> None:
    """Export layer to a temporary file beside path, then rename it over path.

    The temporary name carries the writer's pid (`.<stem>.<pid>.XXXX<suffix>`), so a later
    write of the same file can tell a dead writer's leftovers from a live one's
    (sweep_stale_temps); an interrupted writer removes its own (the signal handlers of
    facedyn.processors.commandline raise, so this `finally` runs).
    """
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.{os.getpid()}.", suffix=path.suffix, dir=path.parent or ".")
    os.close(fd)
    try:
        try:
            ok = layer.Export(tmp)
        except Tf.ErrorException as exc:
            raise TakeError(f"{path}: could not write the layer ({str(exc).strip().splitlines()[-1]})") from None
        if not ok:
            raise TakeError(f"{path}: could not write the layer")
        os.chmod(tmp, 0o666 & ~_umask())
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    reloaded = Sdf.Layer.Find(str(path))
    if reloaded is not None:
        reloaded.Reload(force=True)


def sweep_stale_temps(path: Path) -> list[Path]:
    """Remove the temporary files (and clip folders) of earlier writes of `path` whose writer is gone; return them."""
    removed = []
    prefix = f".{path.stem}."
    for candidate in path.parent.glob(f"{clips.glob_escape(prefix)}*"):
        pid = _writer_pid(candidate.name[len(prefix):])
        if pid is None or _alive(pid):
            continue
        if candidate.is_dir():
            shutil.rmtree(candidate, ignore_errors=True)
        else:
            candidate.unlink(missing_ok=True)
        removed.append(candidate)
    return removed


def _writer_pid(rest: str) -> int | None:
    """The pid in a temporary name's tail (`<pid>.XXXX.usdc`, or `<run>.clips.<pid>.tmp` for clip folders)."""
    parts = rest.split(".")
    if parts[-1] == "tmp" and len(parts) >= 2 and parts[-2].isdigit():
        return int(parts[-2])
    return int(parts[0]) if len(parts) >= 3 and parts[0].isdigit() else None


def _alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's live process
        return True
    return True


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def new_take_root(timing: Timing) -> Sdf.Layer:
    """An empty take root (in memory): the take's timing, defaultPrim, and the take-root marker."""
    layer = Sdf.Layer.CreateAnonymous(".usda")
    timing.apply(layer)
    layer.defaultPrim = PERFORMANCE_PATH.strip("/")
    layer.customLayerData = {"facedyn": {"role": TAKE_ROOT}}
    return layer


def write_take_root(root: Path, sublayers: list[Path], timing: Timing) -> Path:
    """Write a new shot root (.usda) whose subLayers are `sublayers`, strongest first, as given."""
    check_writable(root)
    layer = new_take_root(timing)
    layer.subLayerPaths = [relative_asset_path(p, root.parent) for p in sublayers]
    export_atomically(layer, root)
    return root
