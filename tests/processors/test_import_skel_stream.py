"""`import` streams a UsdSkel rig (issue 19): each chunk's skinning is baked alone, and gives what the whole bake gives.

The truth is UsdSkel.BakeSkinning over the whole take (what import did before it streamed):
its points' time samples are the take's frames, and its points the take's points.
"""
import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom, UsdSkel, Vt

from facedyn.usd.errors import TakeError
from facedyn.usd.skel import plan_skel_bake
from facedyn.usd.source import open_mesh_source, read_usd_mesh
from facedyn.usd.take import read_vec3_samples

from test_import_stream import _import, _streamed_and_whole
from usd_fixtures import bind_rigidly, grid_mesh, one_joint_skeleton

FIRST = 1001


def _rig(path, count: int, animated: bool = True, fps: float = 24.0):
    """A 3x3 grid skinned to one joint keyed every third frame (the frames between are the stage's playback
    frames), with a blend shape keyed on every frame of the middle third, under a skeleton moved on frames
    of its own, at `fps`; without `animated`, nothing is keyed."""
    stage = Usd.Stage.CreateNew(str(path))
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    stage.SetStartTimeCode(FIRST)
    stage.SetEndTimeCode(FIRST + count - 1)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    UsdGeom.SetStageUpAxis(stage, "Y")
    root = UsdSkel.Root.Define(stage, "/Rig")
    skel, anim = one_joint_skeleton(stage, "/Rig/Skel", "head", ["smile"])
    rng = np.random.default_rng(7)
    if animated:
        for t in range(FIRST, FIRST + count, 3):
            anim.CreateTranslationsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(*rng.normal(0, 1, 3))]), t)
            rotation = Gf.Rotation(Gf.Vec3d(0, 1, 0), float(rng.normal(0, 10))).GetQuat()
            anim.CreateRotationsAttr().Set(Vt.QuatfArray([Gf.Quatf(rotation)]), t)
        for t in range(FIRST + count // 3, FIRST + 2 * count // 3):
            anim.CreateBlendShapeWeightsAttr().Set(Vt.FloatArray([float(rng.uniform())]), t)
        op = UsdGeom.Xformable(skel).AddTranslateOp()
        for t in (FIRST + 5, FIRST + count // 2 + 1):
            op.Set(Gf.Vec3d(*rng.normal(0, 2, 3)), t)
    else:
        anim.CreateTranslationsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(1, 2, 3)]))
        anim.CreateRotationsAttr().Set(Vt.QuatfArray([Gf.Quatf(1)]))
    anim.CreateScalesAttr().Set(Vt.Vec3hArray([Gf.Vec3h(1, 1, 1)]))
    points, counts, indices = grid_mesh(3)
    mesh = UsdGeom.Mesh.Define(stage, "/Rig/Face")
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.asarray(points, np.float32) * 3))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray([int(c) for c in counts]))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray([int(i) for i in indices]))
    binding = bind_rigidly(mesh.GetPrim(), skel)
    binding.CreateGeomBindTransformAttr().Set(Gf.Matrix4d(1))
    shape = UsdSkel.BlendShape.Define(stage, "/Rig/Face/smile")
    shape.CreateOffsetsAttr(Vt.Vec3fArray([Gf.Vec3f(0, 3, 0), Gf.Vec3f(1, 0, 0)]))
    shape.CreatePointIndicesAttr(Vt.IntArray([2, 4]))
    binding.CreateBlendShapesAttr(["smile"])
    binding.CreateBlendShapeTargetsRel().SetTargets([shape.GetPath()])
    stage.SetDefaultPrim(root.GetPrim())
    stage.Save()
    return path


def _whole_bake(path):
    """(frames, world points) of /Rig/Face after UsdSkel bakes the whole take (in the rig's centimetres, Y up).

    A mesh bound to one joint is baked rigidly: its points get the blend shapes, its transform the joint.
    """
    stage = Usd.Stage.Open(str(path))
    stage.GetSessionLayer().timeCodesPerSecond = stage.GetTimeCodesPerSecond()  # else baked at 24 per second
    with Usd.EditContext(stage, stage.GetSessionLayer()):
        assert UsdSkel.BakeSkinning(UsdSkel.Root(stage.GetPrimAtPath("/Rig")), Gf.Interval.GetFullInterval())
    prim = stage.GetPrimAtPath("/Rig/Face")
    frames = np.array(prim.GetAttribute("points").GetTimeSamples())
    local = read_vec3_samples(prim.GetAttribute("points"), frames, "whole bake").astype(np.float64)
    xforms = np.array([UsdGeom.XformCache(t).GetLocalToWorldTransform(prim) for t in frames])
    return frames, np.einsum("fni,fij->fnj", local, xforms[:, :3, :3]) + xforms[:, None, 3, :3]


def test_the_planned_time_codes_are_the_whole_bakes(tmp_path):
    rig = _rig(tmp_path / "rig.usda", 100)
    frames, _ = _whole_bake(rig)
    plan = plan_skel_bake(Usd.Stage.Open(str(rig)))
    assert list(plan.time_codes) == ["/Rig/Face"]
    np.testing.assert_array_equal(plan.time_codes["/Rig/Face"], frames)
    np.testing.assert_array_equal(frames, np.arange(FIRST, FIRST + 100))


@pytest.mark.parametrize("fps", [24.0, 120.0])
def test_a_streamed_skel_import_equals_the_whole_bake(tmp_path, monkeypatch, fps):
    """At the session layer's default rate and another: the bake is read at the stage's time codes."""
    rig = _rig(tmp_path / "rig.usda", 150, fps=fps)
    take = _streamed_and_whole(tmp_path, monkeypatch, rig)
    frames, points = _whole_bake(rig)
    np.testing.assert_array_equal(take.frames, frames)
    np.testing.assert_array_equal(frames, np.arange(FIRST, FIRST + 148))  # to the last joint key (every third frame)
    np.testing.assert_allclose(take.points, points, atol=1e-5)
    assert np.ptp(points, axis=0).max() > 1.0  # the rig moves: the comparison is not of a still mesh


def test_reading_a_chunk_bakes_it_and_clears_it(tmp_path):
    rig = _rig(tmp_path / "rig.usda", 60)
    frames, points = _whole_bake(rig)
    source = open_mesh_source(rig)
    np.testing.assert_array_equal(source.time_codes, frames)
    session = source.stage.GetSessionLayer()
    assert session.empty
    np.testing.assert_allclose(source.read(source.time_codes[20:37]), points[20:37], atol=1e-5)
    assert session.empty  # the chunk's bake is gone
    assert source.prim.GetAttribute("points").GetNumTimeSamples() == 0


def test_a_still_skel_rig_has_no_animated_mesh_but_its_skinned_value_reads(tmp_path, capsys):
    rig = _rig(tmp_path / "still.usda", 10, animated=False)
    assert _import(rig, tmp_path / "capture.usdc") == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "still.usda" in err[0] and "no Mesh with time-sampled points" in err[0]
    with pytest.raises(TakeError, match="no Mesh with time-sampled points"):
        open_mesh_source(rig)
    static = read_usd_mesh(rig, first_frame_only=True)  # what `actor --from` reads: the skinned pose
    points, _, _ = grid_mesh(3)
    np.testing.assert_allclose(static.points[0], np.asarray(points) * 3 + [1, 2, 3], atol=1e-5)
