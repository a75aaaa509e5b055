"""`import` bakes a UsdSkel animation (blend shapes and joints) into a take, by UsdSkel's own evaluation."""
import numpy as np
from pxr import Gf, Usd, UsdGeom, UsdSkel, Vt

from facedyn.cli import main
from facedyn.usd.take import read_take

from usd_fixtures import bind_rigidly, one_joint_skeleton

REST = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
FRAMES = [1, 2, 3, 4]

def _small_rig(path):
    """A quad skinned to one joint that slides along x, with a blend shape lifting vertex 2 by 3 units at weight 1."""
    stage = Usd.Stage.CreateNew(str(path))
    stage.SetTimeCodesPerSecond(24)
    stage.SetFramesPerSecond(24)
    UsdGeom.SetStageMetersPerUnit(stage, 0.01)
    UsdGeom.SetStageUpAxis(stage, "Y")
    root = UsdSkel.Root.Define(stage, "/Rig")
    skel, anim = one_joint_skeleton(stage, "/Rig/Skel", "head", ["smile"])
    for i, t in enumerate(FRAMES):
        anim.CreateBlendShapeWeightsAttr().Set(Vt.FloatArray([i / 3.0]), t)
        anim.CreateTranslationsAttr().Set(Vt.Vec3fArray([Gf.Vec3f(i, 0, 0)]), t)
        anim.CreateRotationsAttr().Set(Vt.QuatfArray([Gf.Quatf(1, 0, 0, 0)]), t)
        anim.CreateScalesAttr().Set(Vt.Vec3hArray([Gf.Vec3h(1, 1, 1)]), t)
    mesh = UsdGeom.Mesh.Define(stage, "/Rig/Face")
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(REST))
    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    binding = bind_rigidly(mesh.GetPrim(), skel)
    binding.CreateGeomBindTransformAttr().Set(Gf.Matrix4d(1))
    shape = UsdSkel.BlendShape.Define(stage, "/Rig/Face/smile")
    shape.CreateOffsetsAttr(Vt.Vec3fArray([Gf.Vec3f(0, 3, 0)]))
    shape.CreatePointIndicesAttr(Vt.IntArray([2]))
    binding.CreateBlendShapesAttr(["smile"])
    binding.CreateBlendShapeTargetsRel().SetTargets([shape.GetPath()])
    stage.SetDefaultPrim(root.GetPrim())
    stage.Save()
    return path


def _import(source, output):
    try:
        return main(["import", str(source), "-o", str(output), "-q"])
    except SystemExit as exc:
        return exc.code


def test_import_bakes_blend_shapes_and_a_joint(tmp_path):
    rig = _small_rig(tmp_path / "rig.usda")
    before = rig.read_bytes()
    assert _import(rig, tmp_path / "capture.usdc") == 0
    assert rig.read_bytes() == before  # the source is never edited
    perf, _ = read_take(tmp_path / "take.usda")
    expected = np.stack([REST + [i, 0, 0] + np.outer(np.arange(4) == 2, [0, 3 * i / 3.0, 0]) for i in range(4)])
    np.testing.assert_array_equal(perf.frames, FRAMES)
    assert perf.fps == 24.0
    np.testing.assert_allclose(perf.points, expected, atol=1e-5)


def test_import_bakes_the_ict_rig_driven_by_weights(tmp_path, shared_data):
    ict_rig = shared_data / "ict-facekit" / "ict_face_rig.usdc"
    rig = Usd.Stage.Open(str(ict_rig))
    skin = rig.GetPrimAtPath("/ICTFace/Skin")
    neutral = np.asarray(UsdGeom.Mesh(skin).GetPointsAttr().Get(), np.float64)
    names = ["jawOpen", "mouthSmile_L"]
    truth_offsets = []
    for name in names:
        shape = UsdSkel.BlendShape(rig.GetPrimAtPath(f"/ICTFace/Skin/{name}"))
        offsets = np.zeros_like(neutral)
        indices = shape.GetPointIndicesAttr().Get()
        values = np.asarray(shape.GetOffsetsAttr().Get(), np.float64)
        offsets[np.asarray(indices) if indices else slice(None)] = values
        truth_offsets.append(offsets)
    weights = np.array([[0.0, 0.0], [0.5, 0.0], [1.0, 0.25], [0.2, 1.0]])
    # A performance layer over the rig: a skeleton (one still joint) whose animation keys two weights.
    performance = Usd.Stage.CreateNew(str(tmp_path / "performance.usda"))
    performance.GetRootLayer().subLayerPaths = [str(ict_rig)]
    performance.SetTimeCodesPerSecond(24)
    performance.SetFramesPerSecond(24)
    skel, anim = one_joint_skeleton(performance, "/ICTFace/Skel", "root", names)
    for t, w in enumerate(weights, start=1):
        anim.CreateBlendShapeWeightsAttr().Set(Vt.FloatArray(list(w)), t)
    bind_rigidly(performance.OverridePrim("/ICTFace/Skin"), skel)
    performance.Save()
    assert _import(tmp_path / "performance.usda", tmp_path / "capture.usdc") == 0
    perf, _ = read_take(tmp_path / "take.usda")
    scale = UsdGeom.GetStageMetersPerUnit(rig) / 0.01
    expected = (neutral[None] + np.einsum("fk,knc->fnc", weights, np.stack(truth_offsets))) * scale
    assert perf.points.shape == expected.shape
    np.testing.assert_allclose(perf.points, expected, atol=1e-3)
