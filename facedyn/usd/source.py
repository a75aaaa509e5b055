"""An animated (or static) mesh in any USD file, read as a take holds it: world space, centimetres, Y up.

What `import` and `actor` read from a capture that facedyn did not write. `open_mesh_source`
opens the file once, picks the mesh and its time codes (a skinned or blend-shape rig's mesh
counts as animated: facedyn.usd.skel plans its bake) and reads the static setup (topology,
uvs, facedyn attributes); `MeshSource.read` then reads any frames' points (baking a rig's
skinning for just those frames), checked and made canonical, so a long capture streams
through a range of frames at a time.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pxr import Usd, UsdGeom

from facedyn.performance import UVs, Topology
from facedyn.usd import schema
from facedyn.usd.errors import TakeError
from facedyn.usd.skel import SkelBake, plan_skel_bake
from facedyn.usd.stage import get_prim, layer_name, open_stage
from facedyn.usd.take import (ensure_plausible_points, find_animated_meshes, read_topology, read_uvs, read_vec3_samples,
                              select_time_codes)
from facedyn.usd.takechecks import CENTIMETRES
from facedyn.usd.timing import Timing

BLOCK_FRAMES = 128  # frames converted in float64 at a time


@dataclass
class MeshSource:
    """One mesh of an open stage: its static setup, and its points read a range of frames at a time."""

    stage: Usd.Stage
    prim: Usd.Prim
    time_codes: np.ndarray | None  # (F,) the points' time samples used, None for a static mesh
    topology: Topology
    uvs: UVs | None
    face: schema.FaceAttributes  # the facedyn attributes authored on the source mesh
    timing: Timing  # the source stage's
    skel: SkelBake | None = None  # the stage's UsdSkel rigs, baked a range of frames at a time as they are read

    @property
    def where(self) -> str:
        return f"{layer_name(self.stage)}: {self.prim.GetPath()}"

    @property
    def point_count(self) -> int:
        return self.topology.point_count

    def read(self, time_codes: np.ndarray | None) -> np.ndarray:
        """(F, N, 3) float32 points at `time_codes` (None: the static value) in world space, centimetres, Y up.

        Each frame is checked (finite, a plausible shape, as many points as the topology
        indexes) as it is read, so a fault is found in whichever range holds it. The
        conversion runs in float64, BLOCK_FRAMES frames at a time, so that only the float32
        result is held whole. A rig's skinning is baked for these frames only, while they are read.
        """
        if self.skel is None:
            return self._read(time_codes)
        with self.skel.baked(time_codes, self.prim):
            return self._read(time_codes)

    def _read(self, time_codes: np.ndarray | None) -> np.ndarray:
        geom = UsdGeom.Mesh(self.prim)
        if time_codes is None:
            value = geom.GetPointsAttr().Get()
            if value is None:
                raise TakeError(f"{self.where}.points has no value")
            stamps = np.zeros(1)
            points = np.array(value, dtype=np.float32)[None]  # a copy: USD's own array is read-only
        else:
            stamps = np.asarray(time_codes, dtype=np.float64)
            points = read_vec3_samples(geom.GetPointsAttr(), stamps, self.where + ".points")
        for a in range(0, len(points), BLOCK_FRAMES):
            points[a:a + BLOCK_FRAMES] = self._canonical(points[a:a + BLOCK_FRAMES], stamps[a:a + BLOCK_FRAMES], time_codes is None)
        return points

    def _canonical(self, points: np.ndarray, stamps: np.ndarray, static: bool) -> np.ndarray:
        """Frames of source points checked, then in world space, centimetres, Y up (float64)."""
        points = points.astype(np.float64)
        ensure_plausible_points(points, stamps, self.where + ".points")
        if points.shape[1] != self.point_count:
            raise TakeError(f"{self.where}: {points.shape[1]} points but the topology indexes {self.point_count}")
        codes = [Usd.TimeCode.Default()] if static else [Usd.TimeCode(float(t)) for t in stamps]
        xforms = np.array([np.asarray(UsdGeom.XformCache(code).GetLocalToWorldTransform(self.prim)) for code in codes])
        if not np.allclose(xforms, np.eye(4)):
            points = np.einsum("fni,fij->fnj", points, xforms[:, :3, :3]) + xforms[:, None, 3, :3]
        return _to_canonical_axes(points * (self.timing.meters_per_unit / CENTIMETRES), self.timing.up_axis)


def open_mesh_source(path: Path, mesh: str = "", frames: tuple[float, float] | None = None, static_ok: bool = False,
                     whole_frames: bool = True) -> MeshSource:
    """The mesh at prim path `mesh`, else the only animated one (with `static_ok`, else the only mesh).

    `frames` (first, last) restricts the time codes; with `whole_frames` they must be
    consecutive whole frames at the stage's rate (take.select_time_codes). Nothing but the
    static setup and the time codes is read here.
    """
    stage = open_stage(path)  # refuses layers whose units or rates are not finite and positive
    timing = Timing.from_stage(stage)
    skel = plan_skel_bake(stage)
    if mesh:
        prim = get_prim(stage, mesh)
        if not prim.IsA(UsdGeom.Mesh):
            raise TakeError(f"{layer_name(stage)}: {prim.GetPath()} is not a Mesh")
    else:
        animated = find_animated_meshes(stage)
        animated += [p for p in map(stage.GetPrimAtPath, skel.time_codes) if p not in animated]
        if static_ok and not animated:
            animated = [p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh)]
        if not animated:
            raise TakeError(f"{layer_name(stage)}: no Mesh with time-sampled points (nothing to import)")
        if len(animated) > 1:
            names = ", ".join(str(p.GetPath()) for p in animated)
            raise TakeError(f"{layer_name(stage)}: several {'animated ' if not static_ok else ''}meshes ({names}); choose one with --mesh")
        prim = animated[0]
    geom = UsdGeom.Mesh(prim)
    skinned = skel.time_codes.get(str(prim.GetPath()))
    if static_ok and skinned is None and geom.GetPointsAttr().GetNumTimeSamples() == 0:
        time_codes = None
    else:
        time_codes = select_time_codes(stage, prim, frames, whole_frames, skinned)
    where = f"{layer_name(stage)}: {prim.GetPath()}"
    return MeshSource(stage, prim, time_codes, read_topology(geom, where), read_uvs(geom), schema.FaceAttributes.read(prim),
                      timing, skel if skel.roots else None)


@dataclass
class CanonicalMesh:
    """An animated (or static) USD mesh in world space, centimetres, Y up, read whole."""

    points: np.ndarray  # (F, N, 3) float32
    frames: np.ndarray  # (F,) time codes
    fps: float
    topology: Topology
    uvs: UVs | None
    prim_path: str


def read_usd_mesh(path: Path, mesh: str = "", frames: tuple[float, float] | None = None,
                  first_frame_only: bool = False) -> CanonicalMesh:
    """A USD mesh's points (every frame, or the first only; a static mesh's value) made canonical, in memory."""
    source = open_mesh_source(path, mesh, frames, static_ok=first_frame_only)
    codes = source.time_codes
    if codes is not None and first_frame_only:
        codes = codes[:1]
    points = source.read(codes)
    return CanonicalMesh(points, np.zeros(1) if codes is None else codes, source.timing.time_codes_per_second,
                         source.topology, source.uvs, str(source.prim.GetPath()))


def _to_canonical_axes(points: np.ndarray, up_axis: str) -> np.ndarray:
    """Z-up scenes are turned Y-up (x, y, z) -> (x, z, -y); Y-up ones are left alone."""
    if up_axis == "Z":
        return np.stack([points[..., 0], points[..., 2], -points[..., 1]], axis=-1)
    return points
