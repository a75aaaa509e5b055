"""Take I/O: round trips, composition of result layers over a capture, atomic writes."""
import json
from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf, Usd

from facedyn.geometry import quaternion
from facedyn.performance import UVs, Topology
from facedyn.usd import schema
from facedyn.usd.errors import TakeError
from facedyn.usd.runs import content_id
from facedyn.usd.layers import LayerContent, write_layer, write_take_root
from facedyn.usd.rootedit import attach
from facedyn.usd.take import read_take
from facedyn.usd.timing import Timing

from usd_fixtures import grid_mesh

FRAMES = np.arange(1001, 1009, dtype=np.float64)


def _capture(tmp_path: Path):
    points, counts, indices = grid_mesh(5)
    rng = np.random.default_rng(3)
    world = points[None] + rng.normal(scale=0.1, size=(len(FRAMES),) + points.shape).astype(np.float32)
    uvs = UVs(values=points[:, :2] / 4.0, indices=indices.copy(), interpolation="faceVarying")
    content = LayerContent(
        frames=FRAMES, points=world, topology=Topology(counts, indices), uvs=uvs,
        face=schema.FaceAttributes(role="captured", rigid_weights=np.linspace(0, 1, len(points)).astype(np.float32)),
        skull=schema.SkullAttributes(solver="identity"),
    )
    timing = Timing(120.0, 120.0, FRAMES[0], FRAMES[-1])
    prov = schema.Provenance("import", "test", {"fps": 120.0}, (FRAMES[0], FRAMES[-1]), ["src.usd"])
    capture = write_layer(tmp_path / "capture.usdc", content, timing, prov, define=True)
    root = write_take_root(tmp_path / "take.usda", [capture], timing)
    return root, capture, world, timing


def _skull_motion(n):
    angles = np.linspace(0.0, 0.4, n)
    orient = quaternion.from_axis_angle(np.array([0.2, 1.0, 0.1]), angles)
    translate = np.stack([np.linspace(0, 2, n), np.sin(angles), np.zeros(n)], axis=1)
    return translate, orient


def test_capture_round_trip(tmp_path):
    root, _, world, _ = _capture(tmp_path)
    perf, source = read_take(root)
    np.testing.assert_array_equal(perf.points, world)
    np.testing.assert_array_equal(perf.frames, FRAMES)
    assert perf.fps == 120.0 and perf.role == "captured" and perf.uvs.interpolation == "faceVarying"
    assert perf.rigid_weights[-1] == pytest.approx(1.0)
    t, q = perf.skull()
    np.testing.assert_allclose(t, 0.0)
    np.testing.assert_allclose(q, np.tile([1.0, 0, 0, 0], (len(FRAMES), 1)))
    assert source.mesh_path == "/Performance/Skull/Face" and source.skull_path == "/Performance/Skull"


def test_result_layer_composes_over_capture_and_reproduces_world_points(tmp_path):
    root, capture, world, timing = _capture(tmp_path)
    translate, orient = _skull_motion(len(FRAMES))
    rot = quaternion.to_matrix(orient)
    skull_points = np.einsum("fji,fnj->fni", rot, world - translate[:, None, :]).astype(np.float32)  # R^T (x - t)
    offsets = np.full_like(skull_points, 0.01)
    content = LayerContent(
        frames=FRAMES, points=skull_points, skull_translate=translate, skull_orient=orient, offsets=offsets,
        solve_error=np.linspace(0, 1, len(FRAMES)), face=schema.FaceAttributes(role="stabilized"),
        skull=schema.SkullAttributes(solver="mode-pursuit", landmarks=np.eye(3, dtype=np.float32)),
    )
    prov = schema.Provenance("stabilize", "test", {"method": "mode-pursuit", "path": Path("/x")}, (FRAMES[0], FRAMES[-1]), [str(capture)])
    stabilized = write_layer(tmp_path / "stabilized.usdc", content, timing, prov)
    assert attach(root, stabilized).sublayers == ["./stabilized.usdc", "./capture.usdc"]
    perf, _ = read_take(root)
    assert perf.role == "stabilized"
    np.testing.assert_allclose(perf.world_points(), world, atol=1e-4)
    np.testing.assert_allclose(perf.skull_orient, orient, atol=1e-12)
    np.testing.assert_allclose(perf.offsets, offsets)
    np.testing.assert_allclose(perf.solve_error, np.linspace(0, 1, len(FRAMES)), atol=1e-6)
    np.testing.assert_array_equal(perf.landmarks, np.eye(3))
    # Provenance in the layer metadata and as an applied FacedynProcessorAPI instance.
    layer = Sdf.Layer.OpenAsAnonymous(str(stabilized))
    meta = dict(layer.customLayerData)["facedyn"]
    assert meta["processor"] == "stabilize" and json.loads(meta["parameters"]) == {"method": "mode-pursuit", "path": "/x"}
    assert (layer.timeCodesPerSecond, layer.startTimeCode, layer.endTimeCode) == (120.0, FRAMES[0], FRAMES[-1])
    composed = Usd.Stage.Open(str(root))
    face = composed.GetPrimAtPath("/Performance/Skull/Face")
    runs = {run["processor"]: run for run in schema.read_provenance(face)}
    assert set(runs) == {"import", "stabilize"} and runs["stabilize"]["inputs"] == ["./capture.usdc"]
    assert runs["stabilize"]["role"] == "stabilized" and runs["stabilize"]["inputRuns"] == [content_id(capture)]
    # Every covered frame is authored; offsets carry their interpolation.
    assert list(layer.GetAttributeAtPath("/Performance/Skull/Face.points").GetInfo("timeSamples").keys()) == list(FRAMES)
    assert face.GetAttribute(schema.OFFSETS_ATTR).GetMetadata("interpolation") == "vertex"
    # Muting the result layer shows the capture below it again.
    stage = Usd.Stage.Open(str(root))
    stage.MuteLayer(stabilized.resolve().as_posix())
    points = np.asarray(stage.GetPrimAtPath("/Performance/Skull/Face").GetAttribute("points").Get(FRAMES[3]))
    np.testing.assert_allclose(points, world[3])


def test_frame_range_selects_frames(tmp_path):
    root, _, world, _ = _capture(tmp_path)
    perf, _ = read_take(root, frames=(1003, 1005))
    np.testing.assert_array_equal(perf.frames, [1003, 1004, 1005])
    np.testing.assert_array_equal(perf.points, world[2:5])
    with pytest.raises(TakeError, match="no frames in 2000:2001"):
        read_take(root, frames=(2000, 2001))


def test_failed_write_leaves_previous_file_untouched(tmp_path):
    root, capture, world, timing = _capture(tmp_path)
    before = capture.read_bytes()
    bad = LayerContent(frames=FRAMES, points=np.full_like(world, np.nan))
    prov = schema.Provenance("import", "test", {}, (FRAMES[0], FRAMES[-1]), [])
    with pytest.raises(TakeError, match="non-finite points"):
        write_layer(capture, bad, timing, prov)
    assert capture.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["capture.usdc", "take.usda"]


def test_unwritable_or_missing_output_folder(tmp_path):
    _, _, world, timing = _capture(tmp_path)
    content = LayerContent(frames=FRAMES, points=world)
    prov = schema.Provenance("x", "test", {}, (FRAMES[0], FRAMES[-1]), [])
    with pytest.raises(TakeError, match="does not exist"):
        write_layer(tmp_path / "missing" / "out.usdc", content, timing, prov)
    with pytest.raises(TakeError, match="not a USD file name"):
        write_layer(tmp_path / "out.txt", content, timing, prov)
