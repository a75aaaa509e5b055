"""Reading a take (a composed USD stage in facedyn's layout) into a `Performance`.

The layout (DESIGN.md): an Xform with FacedynSkullAPI whose translate + orient ops are the
skull transform T(t), and below it a Mesh with FacedynFaceAPI whose points are the skin in
skull space. Values are read frame by frame as whole arrays and checked once, so a bad take
fails here with a message naming the file and the prim instead of deep inside an algorithm.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pxr import Usd, UsdGeom

from facedyn.performance import UVs, Performance, Topology, roles
from facedyn.usd import schema
from facedyn.usd.errors import TakeError
from facedyn.usd.layers import frame_extents
from facedyn.usd.layerstack import LEGACY_PROCESSOR_ROLES, is_take_root, layer_metadata, role_of
from facedyn.usd.runs import IN_MEMORY, LAYER, LayerInput, content_id
from facedyn.usd.stage import get_prim, layer_name, open_stage
from facedyn.usd.takechecks import frame_grid_problem, missing_keys_problem, orient_problem, scale_problem, units_problem
from facedyn.usd.timing import Timing


@dataclass(frozen=True)
class TakeSource:
    """Where a Performance came from: what result layers need to point back at it."""

    path: Path  # the take root (or single layer) that was opened
    stage: Usd.Stage
    mesh_path: str
    skull_path: str | None
    timing: Timing
    inputs: tuple[LayerInput, ...] = ()  # the data layers read, strongest first, with their run ids


def read_take(
    path: str | os.PathLike,
    mesh: str | None = None,
    frames: tuple[float, float] | None = None,
) -> tuple[Performance, TakeSource]:
    """Read the face of a take (the mesh with FacedynFaceAPI, or `mesh`) over `frames` (inclusive), all layers composed.

    A processor reads what lies below its own role instead (`read_take_below`).
    """
    return read_stage(open_stage(path), Path(path), mesh, frames)


def read_take_below(
    path: str | os.PathLike, role_name: str, frames: tuple[float, float] | None = None, mesh: str | None = None
) -> tuple[Performance, TakeSource]:
    """Read the take as a processor writing `role_name` sees it: composed from the layers below that role.

    Every layer of that role's rank or higher is muted, and so is any layer of unknown role
    sitting above a muted one, so a re-run never reads its own earlier result or anything
    built on it. Fails, naming what to run, when no layer of the role it reads (Role.reads)
    lies below.
    """
    return read_stage(stage_below(path, role_name), Path(path), mesh, frames)


def stage_below(path: str | os.PathLike, role_name: str) -> Usd.Stage:
    """The take's stage with every layer at or above `role_name`'s rank muted (see read_take_below)."""
    known = roles()
    if role_name not in known:
        raise TakeError(f"{path}: unknown role {role_name!r}; known: {', '.join(known)}")
    wanted = known[role_name]
    stage = open_stage(path)
    stack = stage.GetLayerStack(includeSessionLayers=False)
    muted, cut = [], False
    for layer in reversed(stack[1:]):  # weakest first, so a layer above a muted one is known to be above the cut
        role = role_of(layer_metadata(layer), known)
        if (role is not None and role.rank >= wanted.rank) or (role is None and cut):
            muted.append(layer.identifier)
            cut = True
    stage.MuteAndUnmuteLayers(muted, [])
    if wanted.reads is not None:
        below = {role.name for layer in stage.GetLayerStack(False) if (role := role_of(layer_metadata(layer), known))}
        if wanted.reads not in below:
            writer = next((p for p, r in LEGACY_PROCESSOR_ROLES.items() if r == wanted.reads), None)
            hint = f"; run `usdfacedyn {writer}` first" if writer else ""
            raise TakeError(f"{path}: a {role_name} layer is computed from a {wanted.reads} layer, and none lies below it{hint}")
    return stage


def read_stage(
    stage: Usd.Stage, path: Path, mesh: str | None = None, frames: tuple[float, float] | None = None
) -> tuple[Performance, TakeSource]:
    """read_take on an open stage (e.g. one composed in memory); `path` names it in messages.

    Refuses a take that is not in centimetres, Y up (takechecks.units_problem): facedyn's
    layers copy the take's units, so converting here would leave results that disagree with
    their root; `usdfacedyn import` converts a capture once instead.
    """
    timing = Timing.from_stage(stage)
    problem = scale_problem(timing.meters_per_unit, timing.time_codes_per_second, timing.frames_per_second) \
        or units_problem(timing.meters_per_unit, timing.up_axis)
    if problem:
        raise TakeError(f"{layer_name(stage)}: {problem}")
    mesh_prim = get_prim(stage, mesh) if mesh else find_face_mesh(stage)
    if not mesh_prim.IsA(UsdGeom.Mesh):
        raise TakeError(f"{layer_name(stage)}: {mesh_prim.GetPath()} is a {mesh_prim.GetTypeName() or 'typeless prim'}, expected a Mesh")
    skull_prim = mesh_prim.GetParent()
    if not skull_prim.HasAPI(schema.SKULL_API):
        skull_prim = None
    time_codes = select_time_codes(stage, mesh_prim, frames)
    performance = read_performance(stage, mesh_prim, skull_prim, time_codes)
    source = TakeSource(
        path=path,
        stage=stage,
        mesh_path=str(mesh_prim.GetPath()),
        skull_path=str(skull_prim.GetPath()) if skull_prim else None,
        timing=timing,
        inputs=read_inputs(stage),
    )
    return performance, source


def read_inputs(stage: Usd.Stage) -> tuple[LayerInput, ...]:
    """The data layers of the stage's (unmuted) layer stack with their content ids; roots that only list others are left out."""
    inputs = []
    for layer in stage.GetLayerStack(includeSessionLayers=False):
        if is_take_root(layer):
            continue
        inputs.append(LayerInput(layer.realPath, content_id(layer.realPath), LAYER) if layer.realPath else LayerInput(IN_MEMORY, ""))
    return tuple(inputs)


def find_face_mesh(stage: Usd.Stage) -> Usd.Prim:
    """The one Mesh carrying FacedynFaceAPI."""
    faces = [prim for prim in stage.Traverse() if prim.HasAPI(schema.FACE_API)]
    if not faces:
        raise TakeError(
            f"{layer_name(stage)}: no Mesh with FacedynFaceAPI; convert the capture with `usdfacedyn import` first"
        )
    if len(faces) > 1:
        paths = ", ".join(str(p.GetPath()) for p in faces)
        raise TakeError(f"{layer_name(stage)}: several faces ({paths}); choose one with --mesh")
    return faces[0]


def find_animated_meshes(stage: Usd.Stage) -> list[Usd.Prim]:
    """Every Mesh whose points have more than one time sample."""
    return [
        prim
        for prim in stage.Traverse()
        if prim.IsA(UsdGeom.Mesh) and UsdGeom.Mesh(prim).GetPointsAttr().GetNumTimeSamples() > 1
    ]


def select_time_codes(
    stage: Usd.Stage, mesh_prim: Usd.Prim, frames: tuple[float, float] | None, whole_frames: bool = True,
    samples: np.ndarray | None = None,
) -> np.ndarray:
    """The points' time samples (or the given `samples`), restricted to `frames` (first, last), as float64.

    With `whole_frames` (every reader but a resampling import) they must be consecutive
    whole frames at the stage's rate (takechecks.frame_grid_problem), else a TakeError.
    """
    if samples is None:
        samples = np.asarray(UsdGeom.Mesh(mesh_prim).GetPointsAttr().GetTimeSamples(), dtype=np.float64)
    if samples.size == 0:
        raise TakeError(f"{layer_name(stage)}: {mesh_prim.GetPath()}.points has no time samples (not an animated mesh)")
    if frames is not None:
        first, last = frames
        samples = samples[(samples >= first) & (samples <= last)]
        if samples.size == 0:
            raise TakeError(f"{layer_name(stage)}: {mesh_prim.GetPath()} has no frames in {first:g}:{last:g}")
    problem = frame_grid_problem(samples, stage.GetTimeCodesPerSecond()) if whole_frames else None
    if problem:
        raise TakeError(f"{layer_name(stage)}: {mesh_prim.GetPath()}.points: {problem}")
    return samples


def read_performance(
    stage: Usd.Stage, mesh_prim: Usd.Prim, skull_prim: Usd.Prim | None, time_codes: np.ndarray
) -> Performance:
    where = f"{layer_name(stage)}: {mesh_prim.GetPath()}"
    mesh = UsdGeom.Mesh(mesh_prim)
    topology = read_topology(mesh, where)
    points = read_vec3_samples(mesh.GetPointsAttr(), time_codes, where + ".points")
    if points.shape[1] != topology.point_count:
        raise TakeError(f"{where}: {points.shape[1]} points but the topology indexes {topology.point_count}")
    ensure_plausible_points(points, time_codes, where + ".points")
    timing = Timing.from_stage(stage)
    face = schema.FaceAttributes.read(mesh_prim)
    offsets = None
    offsets_attr = mesh_prim.GetAttribute(schema.OFFSETS_ATTR)
    if offsets_attr and offsets_attr.HasAuthoredValue():
        offsets = read_vec3_samples(offsets_attr, time_codes, where + "." + schema.OFFSETS_ATTR)
        if offsets.shape != points.shape:
            raise TakeError(f"{where}: {offsets.shape[1]} dynamics offsets per frame for {points.shape[1]} points")
    translate = orient = solve_error = landmarks = None
    if skull_prim is not None:
        translate, orient = read_skull_transforms(skull_prim, time_codes)
        skull = schema.SkullAttributes.read(skull_prim)
        landmarks = skull.landmarks
        solve_error = _read_float_samples(skull_prim.GetAttribute(schema.SOLVE_ERROR_ATTR), time_codes)
    return Performance(
        points=points,
        frames=time_codes,
        fps=timing.time_codes_per_second,
        topology=topology,
        skull_translate=translate,
        skull_orient=orient,
        uvs=read_uvs(mesh),
        rest_points=face.rest_points,
        rigid_weights=face.rigid_weights,
        face_vertices=face.face_vertices,
        skin_samples=face.skin_samples,
        alignment_vertices=face.alignment_vertices,
        landmarks=landmarks,
        offsets=offsets,
        solve_error=solve_error,
        role=face.role,
        meters_per_unit=timing.meters_per_unit,
        up_axis=timing.up_axis,
    )


def read_topology(mesh: UsdGeom.Mesh, where: str) -> Topology:
    """faceVertexCounts/Indices, which must not change over time."""
    counts_attr, indices_attr = mesh.GetFaceVertexCountsAttr(), mesh.GetFaceVertexIndicesAttr()
    counts = np.asarray(counts_attr.Get(Usd.TimeCode.EarliestTime()) or [], dtype=np.int32)
    indices = np.asarray(indices_attr.Get(Usd.TimeCode.EarliestTime()) or [], dtype=np.int32)
    if counts.size == 0 or indices.size == 0:
        raise TakeError(f"{where}: the mesh has no faceVertexCounts/faceVertexIndices")
    for attr, first in ((counts_attr, counts), (indices_attr, indices)):
        for t in attr.GetTimeSamples()[1:]:
            if not np.array_equal(np.asarray(attr.Get(t)), first):
                raise TakeError(f"{where}: {attr.GetName()} changes at time {t:g}; facedyn needs one topology for the whole take")
    if counts.sum() != indices.size or (counts < 3).any() or indices.min() < 0:
        raise TakeError(f"{where}: inconsistent topology (faceVertexCounts do not match faceVertexIndices)")
    return Topology(counts, indices)


def read_vec3_samples(attr: Usd.Attribute, time_codes: np.ndarray, where: str) -> np.ndarray:
    """(F, N, 3) float32 from one whole-array Get per frame; every frame must have N values.

    Each frame's Vt array is copied straight into its row of one preallocated array (one
    copy, no per-frame ndarray and no stacking: ~7x faster than np.stack of np.asarray's).
    """
    if not len(time_codes):
        raise TakeError(f"{where}: no frames to read")
    query = Usd.AttributeQuery(attr)
    values = (query.Get(float(t)) for t in time_codes)
    first = next(values)
    if first is None:
        raise TakeError(f"{where}: no values at time {time_codes[0]:g}")
    first = np.asarray(first, dtype=np.float32)
    if first.ndim != 2 or first.shape[1] != 3:
        raise TakeError(f"{where}: expected 3-vectors, got values of shape {first.shape}")
    out = np.empty((len(time_codes), *first.shape), np.float32)
    out[0] = first
    for i, value in enumerate(values, start=1):
        if value is None or len(value) != len(first):
            size = 0 if value is None else len(value)
            raise TakeError(f"{where}: {size} values at time {time_codes[i]:g} but {len(first)} at {time_codes[0]:g}; the point count must not change")
        out[i] = value
    return out


def _read_float_samples(attr: Usd.Attribute, time_codes: np.ndarray) -> np.ndarray | None:
    if not attr or not attr.HasAuthoredValue():
        return None
    query = Usd.AttributeQuery(attr)
    return np.array([query.Get(float(t)) for t in time_codes], dtype=np.float32)


def read_skull_transforms(skull_prim: Usd.Prim, time_codes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-frame translate (F,3) and orient (F,4, w first) of the skull's translate/orient ops.

    An op that is absent is the identity and one with only a default value is constant; one
    that is authored without any value, keyed on only some of the face's frames, non-finite,
    or (orient) not a unit quaternion is a TakeError naming the file and the attribute.
    """
    where = f"{layer_name(skull_prim.GetStage())}: {skull_prim.GetPath()}"
    translate = _skull_op_samples(skull_prim, "xformOp:translate", time_codes, where, lambda v: tuple(v))
    orient = _skull_op_samples(skull_prim, "xformOp:orient", time_codes, where, _quat_wxyz)
    f = len(time_codes)
    translate = np.zeros((f, 3)) if translate is None else translate
    orient = np.tile([1.0, 0.0, 0.0, 0.0], (f, 1)) if orient is None else orient
    if not (np.isfinite(translate).all() and np.isfinite(orient).all()):
        raise TakeError(f"{where} has non-finite skull transforms")
    problem = orient_problem(orient, time_codes)
    if problem:
        raise TakeError(f"{where}.{problem}")
    return translate, orient


def _skull_op_samples(skull_prim: Usd.Prim, name: str, time_codes: np.ndarray, where: str, convert) -> np.ndarray | None:
    """One skull op's per-frame values, None when the op is absent."""
    attr = skull_prim.GetAttribute(name)
    if not attr or not attr.IsAuthored():
        return None
    if not attr.HasAuthoredValue():
        raise TakeError(f"{where}.{name} is authored but has no value (neither time samples nor a default)")
    problem = missing_keys_problem(name, attr.GetTimeSamples(), time_codes) if attr.GetNumTimeSamples() else None
    if problem:
        raise TakeError(f"{where}.{problem}")
    query = Usd.AttributeQuery(attr)
    return np.array([convert(query.Get(float(t))) for t in time_codes], dtype=np.float64)


def _quat_wxyz(q) -> tuple[float, float, float, float]:
    imaginary = q.GetImaginary()
    return (q.GetReal(), imaginary[0], imaginary[1], imaginary[2])


def read_uvs(mesh: UsdGeom.Mesh) -> UVs | None:
    primvar = UsdGeom.PrimvarsAPI(mesh.GetPrim()).GetPrimvar("st")
    if not primvar or not primvar.HasAuthoredValue():
        return None
    values = np.asarray(primvar.Get(), dtype=np.float32)
    indices = np.asarray(primvar.GetIndices(), dtype=np.int32) if primvar.IsIndexed() else None
    return UVs(values=values, indices=indices, interpolation=str(primvar.GetInterpolation()))


def _ensure_finite(values: np.ndarray, time_codes: np.ndarray, where: str) -> None:
    finite = np.isfinite(values).all(axis=(1, 2))
    if not finite.all():
        bad = int(np.argmin(finite))
        raise TakeError(f"{where}: NaN or infinite values at time {time_codes[bad]:g}")


MAX_COORDINATE_CM = 1e6  # 10 km from the origin: no capture volume is that large
MIN_EXTENT_CM = 1e-4  # a frame whose points all coincide (to 1 µm) has no shape to track


def ensure_plausible_points(points: np.ndarray, time_codes: np.ndarray, where: str) -> None:
    """Finite, and frames that are a shape in centimetres: not collapsed to a point, not astronomically far."""
    _ensure_finite(points, time_codes, where)
    bounds = frame_extents(points)  # (F, 2, 3) per-frame lows and highs: one fast pass per coordinate
    far = np.abs(bounds).max(axis=(1, 2)) > MAX_COORDINATE_CM
    if far.any():
        bad = int(np.argmax(far))
        raise TakeError(f"{where}: coordinates beyond {MAX_COORDINATE_CM:g} cm at time {time_codes[bad]:g}; "
                        "check the source's units (metersPerUnit, or import --units for OBJ)")
    extent = (bounds[:, 1] - bounds[:, 0]).max(axis=1)
    flat = extent < MIN_EXTENT_CM
    if flat.any():
        bad = int(np.argmax(flat))
        raise TakeError(f"{where}: every point coincides at time {time_codes[bad]:g} (no shape to track)")



def read_layers(layers: list[Path]) -> Performance:
    """The face of layers stacked in memory (strongest first), without a root on disk."""
    from pxr import Sdf

    from facedyn.usd.timing import Timing

    layer = Sdf.Layer.CreateAnonymous(".usda")
    Timing.from_layer(Sdf.Layer.FindOrOpen(str(layers[-1]))).apply(layer)
    layer.subLayerPaths = [str(p) for p in layers]
    perf, _ = read_stage(Usd.Stage.Open(layer), Path(layers[0]))
    return perf
