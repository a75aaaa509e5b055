"""Blend-shape face rigs as UsdSkel: ICT-FaceKit's layout in, the same layout out.

A rig is a Mesh bound with UsdSkel.BindingAPI whose `skel:blendShapes` names and
`skel:blendShapeTargets` point at UsdSkel.BlendShape prims (offsets, sparse when
`pointIndices` is authored). Shapes named ``identity<digits>`` are identity modes, the rest
expressions. Vertex sets are int[] attributes on the mesh: facedyn's own
(``facedyn:rig:*``, written here) or ICT-FaceKit's (``ict:*``). Everything is converted to
centimetres, Y up, with whole-array conversions. In-betweens and normal offsets are not
read: facedyn evaluates rigs linearly.
"""
from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
from pxr import Sdf, Tf, Usd, UsdGeom, UsdSkel, Vt

from facedyn.rig import FaceRig
from facedyn.usd.errors import TakeError
from facedyn.usd.layers import check_writable, export_atomically
from facedyn.usd.stage import get_prim, layer_name, open_stage
from facedyn.usd.take import read_topology, read_uvs

IDENTITY_SHAPE = re.compile(r"identity\d+$")

FACE_VERTICES_ATTR = "facedyn:rig:faceVertices"
RIGID_VERTICES_ATTR = "facedyn:rig:rigidVertices"
RIGID_WEIGHTS_ATTR = "facedyn:rig:rigidWeights"
LANDMARK_NAMES_ATTR = "facedyn:rig:landmarkNames"
LANDMARK_VERTICES_ATTR = "facedyn:rig:landmarkVertices"
ICT_FACE_VERTICES_ATTR = "ict:faceVertices"
ICT_RIGID_VERTICES_ATTR = "ict:rigidVertices"
ICT_LANDMARKS_ATTR = "ict:landmarks68"

# facedyn's landmark names as entries of the Multi-PIE 68-point order (ict:landmarks68).
MULTIPIE_LANDMARKS = {
    "eye_corner_right": 36,
    "eye_inner_right": 39,
    "eye_inner_left": 42,
    "eye_corner_left": 45,
    "nose_tip": 30,
    "nose_base": 33,
}

# Without a rigid set, vertices that no expression moves farther than this (cm) are rigid.
STILL_CM = 0.01


def read_blendshape_rig(path: str | os.PathLike, mesh: str | None = None) -> FaceRig:
    """Read the blend-shape rig on `mesh` (a prim path), or on the one Mesh that has blend shapes."""
    stage = open_stage(path)
    prim = get_prim(stage, mesh) if mesh else _find_rig_mesh(stage)
    where = f"{layer_name(stage)}: {prim.GetPath()}"
    if not prim.IsA(UsdGeom.Mesh):
        raise TakeError(f"{where} is a {prim.GetTypeName() or 'typeless prim'}, expected a Mesh")
    geom = UsdGeom.Mesh(prim)
    points = np.asarray(geom.GetPointsAttr().Get(Usd.TimeCode.EarliestTime()) or [], dtype=np.float32)
    if points.ndim != 2 or len(points) == 0:
        raise TakeError(f"{where}: the mesh has no points")
    topology = read_topology(geom, where)
    if topology.point_count > len(points):
        raise TakeError(f"{where}: faceVertexIndices use vertex {topology.point_count - 1} but there are {len(points)} points")
    shapes = _read_blend_shapes(prim, len(points), where)
    to_cm = _to_centimetres_y_up(stage)
    identity = [(name, indices, offsets) for name, indices, offsets in shapes if IDENTITY_SHAPE.match(name)]
    expressions = [(name, indices, offsets @ to_cm.T) for name, indices, offsets in shapes if not IDENTITY_SHAPE.match(name)]
    modes = np.zeros((len(identity), len(points), 3), np.float32)
    for mode, (_, indices, offsets) in zip(modes, identity):
        mode[indices] = offsets @ to_cm.T
    rigid = _int_array(prim, RIGID_VERTICES_ATTR, ICT_RIGID_VERTICES_ATTR)
    landmarks = _landmarks(prim, where)
    try:
        return FaceRig(
            name=_rig_name(prim),
            neutral=points @ to_cm.T,
            topology=topology,
            uvs=read_uvs(geom),
            expression_names=tuple(name for name, _, _ in expressions),
            expression_offsets=tuple((indices, offsets) for _, indices, offsets in expressions),
            identity_modes=modes,
            face_vertices=_int_array(prim, FACE_VERTICES_ATTR, ICT_FACE_VERTICES_ATTR),
            rigid_vertices=rigid if rigid is not None else _still_vertices(expressions, len(points)),
            rigid_weights=_array(prim, RIGID_WEIGHTS_ATTR, np.float32),
            landmarks=landmarks,
            metadata={"source": str(path), "mesh": str(prim.GetPath())},
        )
    except ValueError as exc:  # vertex sets or weights in the file that do not fit the mesh
        raise TakeError(f"{where}: {exc}") from None


def _find_rig_mesh(stage: Usd.Stage) -> Usd.Prim:
    meshes = [prim for prim in stage.Traverse() if prim.IsA(UsdGeom.Mesh)]
    if not meshes:
        raise TakeError(f"{layer_name(stage)}: no Mesh prim, expected a face mesh with UsdSkel blend shapes")
    rigs = [prim for prim in meshes if UsdSkel.BindingAPI(prim).GetBlendShapesAttr().HasAuthoredValue()]
    if not rigs:
        names = ", ".join(str(prim.GetPath()) for prim in meshes[:3]) + (", ..." if len(meshes) > 3 else "")
        raise TakeError(f"{layer_name(stage)}: no blend shapes: no Mesh ({names}) has skel:blendShapes")
    if len(rigs) > 1:
        raise TakeError(f"{layer_name(stage)}: several meshes have blend shapes ({', '.join(str(p.GetPath()) for p in rigs)}); choose one with mesh=")
    return rigs[0]


def _read_blend_shapes(prim: Usd.Prim, n: int, where: str) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(name, vertex indices, offsets in file units) of every bound blend shape, in binding order."""
    binding = UsdSkel.BindingAPI(prim)
    names = [str(name) for name in binding.GetBlendShapesAttr().Get() or []]
    targets = binding.GetBlendShapeTargetsRel().GetTargets()
    if not names:
        raise TakeError(f"{where}: no blend shapes (skel:blendShapes is empty or missing)")
    if len(targets) != len(names):
        raise TakeError(f"{where}: {len(names)} skel:blendShapes names but {len(targets)} skel:blendShapeTargets")
    shapes = []
    for name, target in zip(names, targets):
        shape = UsdSkel.BlendShape(prim.GetStage().GetPrimAtPath(target))
        if not shape:
            raise TakeError(f"{where}: blend shape {name!r} targets {target}, which is not a BlendShape prim")
        offsets = np.asarray(shape.GetOffsetsAttr().Get() or [], dtype=np.float32).reshape(-1, 3)
        indices_attr = shape.GetPointIndicesAttr()
        if indices_attr.HasAuthoredValue():
            indices = np.asarray(indices_attr.Get() or [], dtype=np.int32)
        else:
            indices = np.arange(len(offsets), dtype=np.int32)
            if len(offsets) != n:
                raise TakeError(f"{layer_name(prim.GetStage())}: {target} has {len(offsets)} offsets and no pointIndices, expected {n} (one per point)")
        if len(indices) != len(offsets) or (indices.size and (indices.min() < 0 or indices.max() >= n)):
            raise TakeError(f"{layer_name(prim.GetStage())}: {target} has {len(indices)} pointIndices (in [0, {n}) expected) for {len(offsets)} offsets")
        shapes.append((name, indices, offsets))
    return shapes


def _to_centimetres_y_up(stage: Usd.Stage) -> np.ndarray:
    """3x3 matrix taking the stage's units and up axis to facedyn's (cm, Y up, face toward +Z)."""
    scale = UsdGeom.GetStageMetersPerUnit(stage) / 0.01
    if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z:  # (x, y, z) -> (x, z, -y): -Y forward becomes +Z
        return scale * np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]], dtype=np.float32)
    return scale * np.eye(3, dtype=np.float32)


def _array(prim: Usd.Prim, name: str, dtype) -> np.ndarray | None:
    attr = prim.GetAttribute(name)
    return np.asarray(attr.Get(), dtype=dtype) if attr and attr.HasAuthoredValue() else None


def _int_array(prim: Usd.Prim, *names: str) -> np.ndarray | None:
    """The first of the named int[] vertex sets the mesh has."""
    return next((a for a in (_array(prim, name, np.int32) for name in names) if a is not None), None)


def _still_vertices(expressions, n: int) -> np.ndarray:
    """Vertices no expression moves: the generic rigid set of a rig that names none."""
    reach = np.zeros(n, np.float32)
    for _, indices, offsets in expressions:
        np.maximum.at(reach, indices, np.linalg.norm(offsets, axis=1))
    still = np.flatnonzero(reach < STILL_CM)
    return still if 0 < len(still) < n else still[:0]


def _landmarks(prim: Usd.Prim, where: str) -> dict[str, int]:
    names_attr = prim.GetAttribute(LANDMARK_NAMES_ATTR)
    names = list(names_attr.Get()) if names_attr and names_attr.HasAuthoredValue() else None
    vertices = _array(prim, LANDMARK_VERTICES_ATTR, np.int32)
    if names is not None and vertices is not None:
        if len(names) != len(vertices):
            raise TakeError(f"{where}: {len(names)} {LANDMARK_NAMES_ATTR} for {len(vertices)} {LANDMARK_VERTICES_ATTR}")
        return {str(name): int(v) for name, v in zip(names, vertices)}
    multipie = _array(prim, ICT_LANDMARKS_ATTR, np.int32)
    if multipie is not None:
        if len(multipie) != 68:
            raise TakeError(f"{where}: {ICT_LANDMARKS_ATTR} has {len(multipie)} entries, expected 68 (Multi-PIE order)")
        return {name: int(multipie[k]) for name, k in MULTIPIE_LANDMARKS.items()}
    return {}


def _rig_name(prim: Usd.Prim) -> str:
    """The enclosing SkelRoot's name (the character), else the mesh's."""
    ancestor = prim.GetParent()
    while ancestor and not ancestor.IsPseudoRoot():
        if ancestor.IsA(UsdSkel.Root):
            return ancestor.GetName()
        ancestor = ancestor.GetParent()
    return prim.GetName()


def write_blendshape_rig(rig: FaceRig, path: str | os.PathLike, sparse: bool = True) -> Path:
    """Write `rig` as /<name> (SkelRoot) / Face (Mesh) with one BlendShape per shape, atomically.

    Expressions carry pointIndices when `sparse`, full per-point offsets otherwise;
    identity modes are written dense as identity000, identity001, ...
    """
    path = Path(path)
    check_writable(path)
    identity_names = [f"identity{m:03d}" for m in range(rig.identity_count)]
    clashing = [name for name in rig.expression_names if IDENTITY_SHAPE.match(name)]
    if clashing:
        raise ValueError(f"rig {rig.name!r}: expression names {clashing} would read back as identity modes")
    shape_names = list(rig.expression_names) + identity_names
    prim_names = [Tf.MakeValidIdentifier(name) for name in shape_names]
    if len(set(prim_names)) != len(prim_names):
        raise ValueError(f"rig {rig.name!r}: shape names collide as USD prim names: {sorted(n for n in prim_names if prim_names.count(n) > 1)}")

    layer = Sdf.Layer.CreateAnonymous(path.suffix)
    stage = Usd.Stage.Open(layer)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    root = UsdSkel.Root.Define(stage, Sdf.Path.absoluteRootPath.AppendChild(Tf.MakeValidIdentifier(rig.name)))
    stage.SetDefaultPrim(root.GetPrim())
    mesh = UsdGeom.Mesh.Define(stage, root.GetPath().AppendChild("Face"))
    _author_mesh(mesh, rig)

    targets = []
    for k, prim_name in enumerate(prim_names):
        shape = UsdSkel.BlendShape.Define(stage, mesh.GetPath().AppendChild(prim_name))
        if k >= rig.expression_count:
            offsets = rig.identity_modes[k - rig.expression_count]
        elif sparse:
            indices, offsets = rig.expression_offsets[k]
            shape.CreatePointIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(indices, np.int32)))
        else:
            offsets = rig.dense_offsets(rig.expression_names[k])
        shape.CreateOffsetsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(offsets, np.float32)))
        targets.append(shape.GetPath())
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateBlendShapesAttr(Vt.TokenArray(shape_names))
    binding.CreateBlendShapeTargetsRel().SetTargets(targets)
    export_atomically(layer, path)
    return path


def _author_mesh(mesh: UsdGeom.Mesh, rig: FaceRig) -> None:
    """Neutral geometry, topology, uvs and the vertex sets, every value authored explicitly."""
    types = Sdf.ValueTypeNames
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(rig.neutral)))
    mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([rig.neutral.min(axis=0), rig.neutral.max(axis=0)])))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(rig.topology.face_vertex_counts, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(rig.topology.face_vertex_indices, np.int32)))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    mesh.CreateDoubleSidedAttr(False)
    if rig.uvs is not None:
        primvar = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", types.TexCoord2fArray, rig.uvs.interpolation)
        primvar.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(rig.uvs.values, np.float32)))
        if rig.uvs.indices is not None:
            primvar.SetIndices(Vt.IntArray.FromNumpy(np.ascontiguousarray(rig.uvs.indices, np.int32)))
    prim = mesh.GetPrim()
    for name, values in ((FACE_VERTICES_ATTR, rig.face_vertices), (RIGID_VERTICES_ATTR, rig.rigid_vertices)):
        prim.CreateAttribute(name, types.IntArray).Set(Vt.IntArray.FromNumpy(np.ascontiguousarray(values)))
    prim.CreateAttribute(RIGID_WEIGHTS_ATTR, types.FloatArray).Set(Vt.FloatArray.FromNumpy(np.ascontiguousarray(rig.rigid_weights)))
    prim.CreateAttribute(LANDMARK_NAMES_ATTR, types.TokenArray).Set(Vt.TokenArray(list(rig.landmarks)))
    prim.CreateAttribute(LANDMARK_VERTICES_ATTR, types.IntArray).Set(Vt.IntArray.FromNumpy(np.array(list(rig.landmarks.values()), np.int32)))
