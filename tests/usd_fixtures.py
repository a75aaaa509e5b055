"""Small USD mesh caches built in tests (plain USD, no facedyn schemas)."""
from __future__ import annotations

from pathlib import Path

import numpy as np


def write_mesh_cache(path: Path, points: np.ndarray, counts, indices, fps=120.0, first_frame=1001, mesh_path="/Cache/Geo/Face", st=None, up_axis="Y", meters_per_unit=0.01):
    """A plain USD mesh cache (no facedyn schemas): time-sampled points on a Mesh."""
    from pxr import Sdf, Usd, UsdGeom, Vt

    stage = Usd.Stage.CreateNew(str(path))
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    stage.SetStartTimeCode(first_frame)
    stage.SetEndTimeCode(first_frame + len(points) - 1)
    UsdGeom.SetStageUpAxis(stage, up_axis)
    UsdGeom.SetStageMetersPerUnit(stage, meters_per_unit)
    UsdGeom.Xform.Define(stage, Sdf.Path(mesh_path).GetParentPath().GetParentPath())
    UsdGeom.Xform.Define(stage, Sdf.Path(mesh_path).GetParentPath())
    mesh = UsdGeom.Mesh.Define(stage, mesh_path)
    stage.SetDefaultPrim(stage.GetPrimAtPath(Sdf.Path(mesh_path).GetPrefixes()[0]))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.asarray(counts, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.asarray(indices, np.int32)))
    if st is not None:
        values, st_indices = st
        pv = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying)
        pv.Set(Vt.Vec2fArray.FromNumpy(np.asarray(values, np.float32)))
        pv.SetIndices(Vt.IntArray.FromNumpy(np.asarray(st_indices, np.int32)))
    attr = mesh.CreatePointsAttr()
    for i, frame_points in enumerate(points):
        attr.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(frame_points, np.float32)), first_frame + i)
    stage.GetRootLayer().Save()
    return path


def grid_mesh(n: int = 6):
    """A small quad grid: (points (n*n, 3), counts, indices)."""
    ys, xs = np.mgrid[0:n, 0:n]
    points = np.stack([xs.ravel(), ys.ravel(), np.zeros(n * n)], axis=1).astype(np.float32)
    quads = []
    for r in range(n - 1):
        for c in range(n - 1):
            a = r * n + c
            quads.append([a, a + 1, a + n + 1, a + n])
    quads = np.asarray(quads, np.int32)
    return points, np.full(len(quads), 4, np.int32), quads.ravel()


def one_joint_skeleton(stage, path: str, joint: str, blend_shapes=()):
    """A UsdSkel Skeleton at `path` with one joint at the identity and its Animation (`path`/Anim) bound as its source."""
    from pxr import Gf, UsdSkel

    skel = UsdSkel.Skeleton.Define(stage, path)
    skel.CreateJointsAttr([joint])
    skel.CreateBindTransformsAttr([Gf.Matrix4d(1)])
    skel.CreateRestTransformsAttr([Gf.Matrix4d(1)])
    anim = UsdSkel.Animation.Define(stage, f"{path}/Anim")
    anim.CreateJointsAttr([joint])
    anim.CreateBlendShapesAttr(list(blend_shapes))
    UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
    return skel, anim


def bind_rigidly(prim, skel):
    """Skin `prim` to the skeleton's one joint with weight 1 (its UsdSkel.BindingAPI, for blend shapes)."""
    from pxr import UsdSkel

    binding = UsdSkel.BindingAPI.Apply(prim)
    binding.CreateSkeletonRel().SetTargets([skel.GetPath()])
    binding.CreateJointIndicesPrimvar(constant=True, elementSize=1).Set([0])
    binding.CreateJointWeightsPrimvar(constant=True, elementSize=1).Set([1.0])
    return binding
