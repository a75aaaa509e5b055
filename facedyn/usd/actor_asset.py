"""Actor assets (`actor.usda`): one actor's skull frame and face setup as USD.

Layout, with facedyn's existing API schemas so a viewer without the plugin still sees a
mesh (the actor's neutral in its skull space):

    def Xform "Actor" (kind = "component")             customLayerData: facedyn role "actor"
        def Xform "Skull" (FacedynSkullAPI)             skull landmarks, solver "actor"
            def Mesh "Neutral" (FacedynFaceAPI)         points = rest points = the neutral,
                                                        topology, st, rigid weights, face
                                                        vertices, skin samples, eye corners
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from pxr import Kind, Sdf, Usd, UsdGeom, Vt

import facedyn
from facedyn.performance import Actor
from facedyn.usd import schema
from facedyn.usd.errors import TakeError
from facedyn.usd.layers import check_writable, export_atomically
from facedyn.usd.stage import layer_name, open_stage
from facedyn.usd.take import read_topology, read_uvs
from facedyn.usd.timing import Timing

ACTOR_ROLE = "actor"
ROOT_PATH, SKULL_PATH, MESH_PATH = "/Actor", "/Actor/Skull", "/Actor/Skull/Neutral"


def write_actor(path: str | os.PathLike, actor: Actor) -> Path:
    """Write `actor` as a small .usda asset, atomically."""
    path = Path(path)
    check_writable(path)
    layer = Sdf.Layer.CreateAnonymous(path.suffix)
    Timing(24.0, 24.0, 0.0, 0.0).apply(layer)
    layer.customLayerData = {"facedyn": {"role": ACTOR_ROLE, "name": actor.name, "source": actor.source,
                                         "skullFrame": actor.skull_frame, "version": f"facedyn {facedyn.__version__}"}}
    stage = Usd.Stage.Open(layer)
    root = UsdGeom.Xform.Define(stage, ROOT_PATH).GetPrim()
    Usd.ModelAPI(root).SetKind(Kind.Tokens.component)
    skull = UsdGeom.Xform.Define(stage, SKULL_PATH).GetPrim()
    schema.SkullAttributes(solver="actor", landmarks=actor.landmarks).write(skull)
    mesh = UsdGeom.Mesh.Define(stage, MESH_PATH)
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(actor.neutral)))
    mesh.CreateExtentAttr(Vt.Vec3fArray.FromNumpy(np.stack([actor.neutral.min(0), actor.neutral.max(0)]).astype(np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(actor.topology.face_vertex_counts, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.ascontiguousarray(actor.topology.face_vertex_indices, np.int32)))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    if actor.uvs is not None:
        primvar = UsdGeom.PrimvarsAPI(mesh.GetPrim()).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, actor.uvs.interpolation)
        primvar.Set(Vt.Vec2fArray.FromNumpy(np.ascontiguousarray(actor.uvs.values, np.float32)))
        if actor.uvs.indices is not None:
            primvar.SetIndices(Vt.IntArray.FromNumpy(np.ascontiguousarray(actor.uvs.indices, np.int32)))
    schema.FaceAttributes(role=None, rest_points=actor.neutral, skin_samples=actor.skin_samples, rigid_weights=actor.rigid_weights,
                          face_vertices=actor.face_vertices, alignment_vertices=actor.alignment_vertices).write(mesh.GetPrim())
    layer.defaultPrim = ROOT_PATH.strip("/")
    export_atomically(layer, path)
    return path


def read_actor_for(path: str | os.PathLike, topology, take: str | os.PathLike) -> Actor:
    """The actor in an actor asset, checked to apply to `take` (tracked on the same mesh)."""
    actor = read_actor(path)
    if actor.topology.fingerprint() != topology.fingerprint():
        raise TakeError(f"{path}: the actor's mesh topology ({actor.topology.point_count} points) differs from {take}'s "
                        f"({topology.point_count} points); an actor applies to takes tracked on its own mesh")
    return actor


def read_actor(path: str | os.PathLike) -> Actor:
    """The actor in an actor asset, or a TakeError naming the file and what is missing."""
    stage = open_stage(path)
    where = layer_name(stage)
    data = dict(stage.GetRootLayer().customLayerData).get("facedyn", {})
    if not isinstance(data, dict) or data.get("role") != ACTOR_ROLE:
        raise TakeError(f"{where}: not an actor asset (make one with `usdfacedyn actor`)")
    prim = stage.GetPrimAtPath(MESH_PATH)
    if not prim or not prim.IsA(UsdGeom.Mesh):
        raise TakeError(f"{where}: no Mesh at {MESH_PATH}")
    mesh = UsdGeom.Mesh(prim)
    topology = read_topology(mesh, f"{where}: {MESH_PATH}")
    neutral = np.asarray(mesh.GetPointsAttr().Get() or [], dtype=np.float32)
    if neutral.shape != (topology.point_count, 3) or not np.isfinite(neutral).all():
        raise TakeError(f"{where}: {MESH_PATH}.points must hold {topology.point_count} finite points")
    face = schema.FaceAttributes.read(prim)
    skull = schema.SkullAttributes.read(stage.GetPrimAtPath(SKULL_PATH))
    actor = Actor(name=str(data.get("name", Path(path).stem)), neutral=neutral, topology=topology, uvs=read_uvs(mesh),
                  rigid_weights=face.rigid_weights, face_vertices=face.face_vertices, skin_samples=face.skin_samples,
                  alignment_vertices=face.alignment_vertices, landmarks=skull.landmarks, source=str(data.get("source", "")))
    n = topology.point_count
    for name in ("rigid_weights", "face_vertices", "skin_samples", "alignment_vertices"):
        value = getattr(actor, name)
        if value is None:
            continue
        bad = len(value) != n if name == "rigid_weights" else (value.size and (value.min() < 0 or value.max() >= n))
        if bad:
            raise TakeError(f"{where}: {MESH_PATH} {name} do not fit its {n} points")
    return actor
