"""Wrong takes are refused at every reader (and listed by validate), never read silently wrong."""
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Sdf, UsdGeom

from facedyn.geometry import quaternion
from facedyn.performance import Topology
from facedyn.usd import schema
from facedyn.usd.errors import TakeError
from facedyn.usd.layers import LayerContent, write_layer, write_take_root
from facedyn.usd.take import read_take, read_take_below
from facedyn.usd.takechecks import frame_grid_problem, missing_keys_problem, orient_problem, units_problem
from facedyn.usd.timing import Timing
from facedyn.usd.validate import validate_take

from usd_fixtures import grid_mesh

SKULL = "/Performance/Skull"


def _take(tmp_path: Path, frames=np.arange(1001, 1007, dtype=np.float64), capture_fps=120.0, root_fps=120.0, skull=False):
    """A capture (and optionally a stabilized layer with a turning skull) under a take root."""
    points, counts, indices = grid_mesh(4)
    world = np.stack([points + 0.1 * i for i in range(len(frames))]).astype(np.float32)
    topology = Topology(counts, indices)
    content = LayerContent(frames=frames, points=world, topology=topology, face=schema.FaceAttributes(role="captured"),
                           skull=schema.SkullAttributes(solver="identity"))
    timing = Timing(capture_fps, capture_fps, frames[0], frames[-1])
    layers = [write_layer(tmp_path / "capture.usdc", content, timing, schema.Provenance("import", "test", {}, (frames[0], frames[-1]), []), define=True)]
    if skull:
        orient = quaternion.from_axis_angle(np.array([0.0, 1.0, 0.0]), np.linspace(0, 0.3, len(frames)))
        stabilized = LayerContent(frames=frames, points=world, topology=topology, face=schema.FaceAttributes(role="stabilized"),
                                  skull=schema.SkullAttributes(solver="test"), skull_translate=np.zeros((len(frames), 3)), skull_orient=orient)
        prov = schema.Provenance("stabilize", "test", {}, (frames[0], frames[-1]), [])
        layers.insert(0, write_layer(tmp_path / "stabilized.usdc", stabilized, timing, prov))
    return write_take_root(tmp_path / "take.usda", layers, Timing(root_fps, root_fps, frames[0], frames[-1]))


def _refused(root: Path, *needles: str, role: str | None = None) -> str:
    with pytest.raises(TakeError) as caught:
        read_take_below(root, role) if role else read_take(root)
    message = str(caught.value)
    assert str(root) in message and "\n" not in message
    for needle in needles:
        assert needle in message, message
    return message


def _errors(root: Path, validator: str) -> list:
    found = [f for f in validate_take(root) if f.severity == "error" and f.validator == validator]
    assert found, [f.__dict__ for f in validate_take(root)]
    assert all(f.file for f in found)
    return found


# The checks themselves, on arrays.

def test_frame_grid_problems_name_the_fix():
    assert frame_grid_problem(np.arange(1001.0, 1010.0), 120.0) is None
    assert frame_grid_problem(np.array([7.0]), 24.0) is None
    gap = frame_grid_problem(np.array([1.0, 2.0, 5.0, 6.0]), 24.0)
    assert "2 frame(s) missing" in gap and "between 2 and 5" in gap and "--fps 24" in gap
    sparse = frame_grid_problem(np.arange(4004.0, 4040.0, 4.0), 120.0)
    assert "30 fps capture under a 120" in sparse and "--fps 30" in sparse
    between = frame_grid_problem(np.arange(10.0, 12.0, 0.2), 24.0)
    assert "not a whole frame" in between and "120 fps capture" in between and "--fps 120" in between


def test_units_orient_and_key_problems():
    assert units_problem(0.01, "Y") is None
    assert "metersPerUnit is 1" in units_problem(1.0, "Y") and "usdfacedyn import" in units_problem(1.0, "Y")
    assert "upAxis is Z" in units_problem(0.01, "Z")
    assert "metersPerUnit" in units_problem(float("nan"), "Y")
    frames = np.arange(3.0)
    assert orient_problem(np.array([[1.0, 0, 0, 0], [0, 0, 1, 0], [0.6, 0.8, 0, 0]]), frames) is None
    assert "time 1 has length 0" in orient_problem(np.array([[1.0, 0, 0, 0], [0, 0, 0, 0], [1, 0, 0, 0]]), frames)
    assert "length 2" in orient_problem(np.array([[2.0, 0, 0, 0]] * 3), frames)
    assert missing_keys_problem("xformOp:orient", np.arange(10.0), frames + 2) is None
    assert "keyed at 2 of the face's 3 frames (first missing 0)" in missing_keys_problem("xformOp:orient", np.array([1.0, 2.0]), frames)
    assert "keyed at 0" in missing_keys_problem("t", np.array([]), frames)


# At the readers, and in validate.

def test_a_valid_take_reads_and_validates(tmp_path):
    root = _take(tmp_path, skull=True)
    perf, _ = read_take(root)
    assert perf.frame_count == 6 and perf.skull_orient is not None
    assert not [f for f in validate_take(root) if f.severity == "error"]


def test_gaps_and_fractional_time_codes_are_refused(tmp_path):
    (tmp_path / "gap").mkdir()
    root = _take(tmp_path / "gap", frames=np.array([1001.0, 1002.0, 1005.0, 1006.0]))
    _refused(root, "2 frame(s) missing", "--fps 120")
    _refused(root, "missing", role="stabilized")  # what a processor reads
    _errors(root, "facedyn:Frames")
    perf, _ = read_take(root, frames=(1005, 1006))  # a frame range without the gap reads
    assert list(perf.frames) == [1005.0, 1006.0]
    (tmp_path / "half").mkdir()
    root = _take(tmp_path / "half", frames=np.arange(1001.0, 1004.0, 0.5))
    _refused(root, "1001.5 is not a whole frame", "240 fps capture", "--fps 240")


def test_a_30fps_capture_under_a_120fps_root_is_refused(tmp_path):
    root = _take(tmp_path, capture_fps=30.0, root_fps=120.0)
    _refused(root, "30 fps capture under a 120", "--fps 30", role="stabilized")
    _errors(root, "facedyn:Frames")
    _errors(root, "facedyn:Timing")


@pytest.mark.parametrize("meters_per_unit, up_axis, needle", [(1.0, "Y", "metersPerUnit is 1"), (0.01, "Z", "upAxis is Z")])
def test_a_take_not_in_centimetres_y_up_is_refused(tmp_path, meters_per_unit, up_axis, needle):
    root = _take(tmp_path)
    layer = Sdf.Layer.FindOrOpen(str(root))
    layer.pseudoRoot.SetInfo(UsdGeom.Tokens.metersPerUnit, meters_per_unit)
    layer.pseudoRoot.SetInfo(UsdGeom.Tokens.upAxis, up_axis)
    layer.Save()
    _refused(root, needle, "usdfacedyn import", role="stabilized")
    assert needle in _errors(root, "facedyn:Units")[0].message


def _edit_skull(root: Path, edit) -> None:
    layer = Sdf.Layer.FindOrOpen(str(root.parent / "stabilized.usdc"))
    edit(layer.GetAttributeAtPath(SKULL + ".xformOp:orient"))
    layer.Save()


def test_skull_ops_without_a_value_are_refused(tmp_path):
    root = _take(tmp_path)
    capture = Sdf.Layer.FindOrOpen(str(tmp_path / "capture.usdc"))
    attr = capture.GetAttributeAtPath(SKULL + ".xformOp:orient")
    attr.ClearDefaultValue()
    capture.Save()
    _refused(root, "xformOp:orient is authored but has no value", role="stabilized")
    found = _errors(root, "facedyn:Skull")
    assert found[0].prim == SKULL


def test_a_skull_keyed_on_some_frames_is_refused(tmp_path):
    root = _take(tmp_path, skull=True)

    def drop_half(spec):
        for t in list(spec.layer.ListTimeSamplesForPath(spec.path))[::2]:
            spec.layer.EraseTimeSample(spec.path, t)

    _edit_skull(root, drop_half)
    message = _refused(root, "keyed at 3 of the face's 6 frames", role="quasistatic")
    assert "xformOp:orient" in message
    _errors(root, "facedyn:Skull")


@pytest.mark.parametrize("quat, needle", [(Gf.Quatd(0, 0, 0, 0), "length 0"), (Gf.Quatd(2, 0, 0, 0), "length 2")])
def test_zero_and_non_unit_quaternions_are_refused(tmp_path, quat, needle):
    root = _take(tmp_path, skull=True)
    _edit_skull(root, lambda spec: spec.layer.SetTimeSample(spec.path, 1003.0, quat))
    _refused(root, "xformOp:orient at time 1003", needle, role="quasistatic")
    assert needle in _errors(root, "facedyn:Skull")[0].message
