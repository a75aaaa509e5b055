"""Reading and writing UsdSkel blend-shape rigs: ICT-FaceKit, round trips, fallbacks, errors."""
import time
from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf, Usd, UsdGeom, UsdSkel

from facedyn.sim.default_face import default_face
from facedyn.rig import LANDMARK_NAMES
from facedyn.usd.errors import TakeError
from facedyn.usd.blendshape_rig import read_blendshape_rig, write_blendshape_rig

ICT = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "ict-facekit" / "ict_face_rig.usdc"
needs_ict = pytest.mark.skipif(not ICT.is_file(), reason=f"ICT-FaceKit rig not found at {ICT} (../shared/data)")


@pytest.fixture(scope="module")
def ict():
    if not ICT.is_file():
        pytest.skip(f"ICT-FaceKit rig not found at {ICT} (../shared/data)")
    start = time.perf_counter()
    rig = read_blendshape_rig(ICT)
    return rig, time.perf_counter() - start


@pytest.fixture(scope="module")
def small_face():
    return default_face(8)


def assert_same_rig(read, written):
    assert read.name == written.name
    np.testing.assert_array_equal(read.neutral, written.neutral)
    np.testing.assert_array_equal(read.topology.face_vertex_counts, written.topology.face_vertex_counts)
    np.testing.assert_array_equal(read.topology.face_vertex_indices, written.topology.face_vertex_indices)
    np.testing.assert_array_equal(read.uvs.values, written.uvs.values)
    np.testing.assert_array_equal(read.uvs.indices, written.uvs.indices)
    assert read.uvs.interpolation == written.uvs.interpolation
    assert read.expression_names == written.expression_names
    for name in written.expression_names:
        np.testing.assert_array_equal(read.dense_offsets(name), written.dense_offsets(name))
    np.testing.assert_array_equal(read.identity_modes, written.identity_modes)
    np.testing.assert_array_equal(read.face_vertices, written.face_vertices)
    np.testing.assert_array_equal(read.rigid_vertices, written.rigid_vertices)
    np.testing.assert_array_equal(read.rigid_weights, written.rigid_weights)
    assert read.landmarks == written.landmarks


def test_ict_loads_quickly_with_all_its_parts(ict):
    rig, seconds = ict
    assert seconds < 2.0
    assert rig.name == "ICTFace"
    assert rig.point_count == 11248 and len(rig.topology.face_vertex_counts) == 11144
    assert rig.expression_count == 53 and rig.identity_count == 10
    assert {"jawOpen", "mouthSmile_L", "eyeBlink_R", "browInnerUp_L", "cheekPuff_R"} <= set(rig.expression_names)
    assert len(rig.face_vertices) == 9409 and len(rig.rigid_vertices) == 910
    np.testing.assert_array_equal(rig.rigid_weights[rig.rigid_vertices], 1.0)
    assert ((rig.rigid_weights >= 0) & (rig.rigid_weights <= 1)).all()
    assert set(rig.landmarks) == set(LANDMARK_NAMES)
    p = {name: rig.neutral[i] for name, i in rig.landmarks.items()}
    assert p["eye_corner_left"][0] > p["eye_inner_left"][0] > 0 > p["eye_inner_right"][0] > p["eye_corner_right"][0]
    assert p["nose_base"][1] < p["nose_tip"][1] < p["eye_inner_left"][1]
    assert rig.uvs.interpolation == "faceVarying" and rig.uvs.indices is not None
    tiles = np.unique(np.floor(rig.uvs.values[:, 0]))
    assert len(tiles) >= 2


def test_ict_expressions_match_the_file(ict):
    rig, _ = ict
    assert np.linalg.norm(rig.dense_offsets("jawOpen"), axis=1).max() == pytest.approx(4.2, abs=0.05)
    stage = Usd.Stage.Open(str(ICT))
    weights = rig.weights_from({"jawOpen": 0.8, "mouthSmile_L": 0.5, "eyeBlink_R": 1.0})
    expected = rig.neutral.astype(np.float64).copy()
    for name, w in (("jawOpen", 0.8), ("mouthSmile_L", 0.5), ("eyeBlink_R", 1.0)):
        shape = UsdSkel.BlendShape(stage.GetPrimAtPath(f"/ICTFace/Skin/{name}"))
        expected[np.asarray(shape.GetPointIndicesAttr().Get())] += w * np.asarray(shape.GetOffsetsAttr().Get())
    np.testing.assert_allclose(rig.evaluate(weights), expected, atol=1e-4)
    identity = np.asarray(UsdSkel.BlendShape(stage.GetPrimAtPath("/ICTFace/Skin/identity003")).GetOffsetsAttr().Get())
    np.testing.assert_array_equal(rig.identity_modes[3], identity)
    actor = rig.make_actor(seed=0)
    assert 0.5 < np.linalg.norm(actor.neutral - rig.neutral, axis=1).max() < 5.0


def test_default_face_uses_ict_expression_names(ict, small_face):
    """So that one set of (Live Link) curves drives both rigs."""
    rig, _ = ict
    assert set(small_face.expression_names) <= set(rig.expression_names)


@needs_ict
def test_ict_round_trip(ict, tmp_path):
    rig, _ = ict
    path = write_blendshape_rig(rig, tmp_path / "ict.usdc")
    assert_same_rig(read_blendshape_rig(path), rig)


@pytest.mark.parametrize("sparse", [True, False])
def test_round_trip_with_and_without_point_indices(small_face, tmp_path, sparse):
    path = write_blendshape_rig(small_face, tmp_path / "face.usdc", sparse=sparse)
    stage = Usd.Stage.Open(str(path))
    jaw = UsdSkel.BlendShape(stage.GetPrimAtPath("/DefaultFace/Face/jawOpen"))
    assert jaw.GetPointIndicesAttr().HasAuthoredValue() == sparse
    assert not UsdSkel.BlendShape(stage.GetPrimAtPath("/DefaultFace/Face/identity000")).GetPointIndicesAttr().HasAuthoredValue()
    assert UsdGeom.GetStageMetersPerUnit(stage) == 0.01 and UsdGeom.GetStageUpAxis(stage) == "Y"
    assert_same_rig(read_blendshape_rig(path), small_face)


def test_a_plain_rig_gets_generic_masks(small_face, tmp_path):
    """Without vertex sets: the face is every vertex and the rigid set is what no expression moves."""
    path = write_blendshape_rig(small_face, tmp_path / "plain.usda")
    layer = Sdf.Layer.FindOrOpen(str(path))
    mesh = layer.GetPrimAtPath("/DefaultFace/Face")
    for name in [prop.name for prop in mesh.properties if prop.name.startswith("facedyn:rig:")]:
        mesh.RemoveProperty(mesh.properties[name])
    layer.Save()
    rig = read_blendshape_rig(path)
    np.testing.assert_array_equal(rig.face_vertices, np.arange(rig.point_count))
    moved = np.zeros(rig.point_count, bool)
    for indices, offsets in rig.expression_offsets:
        moved[indices[np.linalg.norm(offsets, axis=1) >= 0.01]] = True
    np.testing.assert_array_equal(rig.rigid_vertices, np.flatnonzero(~moved))
    assert rig.landmarks == {}
    np.testing.assert_array_equal(rig.rigid_weights[rig.rigid_vertices], 1.0)


def test_units_and_up_axis_become_centimetres_y_up(small_face, tmp_path):
    path = write_blendshape_rig(small_face, tmp_path / "metres.usda")
    layer = Sdf.Layer.FindOrOpen(str(path))
    layer.pseudoRoot.SetInfo(UsdGeom.Tokens.metersPerUnit, 0.1)
    layer.pseudoRoot.SetInfo(UsdGeom.Tokens.upAxis, UsdGeom.Tokens.z)
    layer.Save()
    rig = read_blendshape_rig(path)
    x, y, z = (10.0 * small_face.neutral).T
    np.testing.assert_allclose(rig.neutral, np.stack([x, z, -y], 1), rtol=1e-6, atol=1e-5)
    x, y, z = (10.0 * small_face.dense_offsets("jawOpen")).T
    np.testing.assert_allclose(rig.dense_offsets("jawOpen"), np.stack([x, z, -y], 1), rtol=1e-6, atol=1e-5)


def write_stage(path: Path, build) -> Path:
    stage = Usd.Stage.CreateNew(str(path))
    build(stage)
    stage.Save()
    return path


def a_mesh(stage, path="/Head"):
    mesh = UsdGeom.Mesh.Define(stage, path)
    mesh.CreatePointsAttr([(0, 0, 0), (1, 0, 0), (0, 1, 0)])
    mesh.CreateFaceVertexCountsAttr([3])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2])
    return mesh


def with_shape(stage, offsets, indices=None, names=("jawOpen",)):
    mesh = a_mesh(stage)
    shape = UsdSkel.BlendShape.Define(stage, "/Head/jawOpen")
    shape.CreateOffsetsAttr(offsets)
    if indices is not None:
        shape.CreatePointIndicesAttr(indices)
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateBlendShapesAttr(list(names))
    binding.CreateBlendShapeTargetsRel().SetTargets([shape.GetPath()])


def bad_vertex_set(stage):
    with_shape(stage, [(0, 0, 1)], [2])
    stage.GetPrimAtPath("/Head").CreateAttribute("ict:faceVertices", Sdf.ValueTypeNames.IntArray).Set([0, 5])


def bad_landmarks(stage):
    with_shape(stage, [(0, 0, 1)], [2])
    stage.GetPrimAtPath("/Head").CreateAttribute("ict:landmarks68", Sdf.ValueTypeNames.IntArray).Set([0, 1])


def test_a_minimal_hand_written_rig_reads(tmp_path):
    path = write_stage(tmp_path / "tiny.usda", lambda s: with_shape(s, [(0, 0, 1)], [2]))
    rig = read_blendshape_rig(path)
    assert rig.name == "Head" and rig.expression_names == ("jawOpen",) and rig.identity_count == 0
    np.testing.assert_array_equal(rig.evaluate([1.0])[2], [0, 1, 1])


@pytest.mark.parametrize(
    "build, mesh, message",
    [
        (lambda s: UsdGeom.Xform.Define(s, "/Root"), None, r"tiny\.usda: no Mesh prim"),
        (lambda s: a_mesh(s), None, r"tiny\.usda: no blend shapes: no Mesh \(/Head\)"),
        (lambda s: a_mesh(s), "/Head", r"tiny\.usda: /Head: no blend shapes"),
        (lambda s: with_shape(s, [(0, 0, 1)]), None, r"/Head/jawOpen has 1 offsets and no pointIndices, expected 3"),
        (lambda s: with_shape(s, [(0, 0, 1)], [7]), None, r"/Head/jawOpen has 1 pointIndices \(in \[0, 3\) expected\)"),
        (lambda s: with_shape(s, [(0, 0, 1)], [0], ("a", "b")), None, r"2 skel:blendShapes names but 1 skel:blendShapeTargets"),
        (lambda s: a_mesh(s), "/Nowhere", r"tiny\.usda: no prim at /Nowhere"),
        (bad_vertex_set, None, r"tiny\.usda: /Head: rig 'Head': face_vertices must be vertex indices in \[0, 3\)"),
        (bad_landmarks, None, r"tiny\.usda: /Head: ict:landmarks68 has 2 entries, expected 68"),
        (lambda s: UsdGeom.Xform.Define(s, "/Root"), "/Root", r"tiny\.usda: /Root is a Xform, expected a Mesh"),
    ],
)
def test_bad_rigs_give_one_line_errors(tmp_path, build, mesh, message):
    path = write_stage(tmp_path / "tiny.usda", build)
    with pytest.raises(TakeError, match=message) as caught:
        read_blendshape_rig(path, mesh=mesh)
    assert "\n" not in str(caught.value)
    assert isinstance(caught.value, ValueError)


def test_missing_and_non_usd_files(tmp_path):
    with pytest.raises(TakeError, match=r"nothing\.usdc: no such file"):
        read_blendshape_rig(tmp_path / "nothing.usdc")
    garbage = tmp_path / "garbage.usda"
    garbage.write_text("this is not USD\n")
    with pytest.raises(TakeError, match=r"garbage\.usda: not a readable USD file"):
        read_blendshape_rig(garbage)
    text = tmp_path / "notes.txt"
    text.write_text("hello\n")
    with pytest.raises(TakeError, match=r"notes\.txt: not a USD file"):
        read_blendshape_rig(text)


def test_writer_refuses_expressions_named_like_identity_modes(small_face, tmp_path):
    from dataclasses import replace

    renamed = replace(small_face, expression_names=("identity007",) + small_face.expression_names[1:])
    with pytest.raises(ValueError, match="would read back as identity modes"):
        write_blendshape_rig(renamed, tmp_path / "bad.usdc")
    assert not (tmp_path / "bad.usdc").exists()
