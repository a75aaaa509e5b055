"""Live Link Face CSVs: timecodes, truncated rows and ARKit -> rig name mapping."""
import numpy as np
import pytest

from facedyn.io import livelink
from facedyn.io.errors import InputError

# The 53 expression shapes of the ICT-FaceKit rig (../shared/data/ict-facekit), in its order.
ICT_SHAPES = [
    "browDown_L", "browDown_R", "browInnerUp_L", "browInnerUp_R", "browOuterUp_L", "browOuterUp_R",
    "cheekPuff_L", "cheekPuff_R", "cheekSquint_L", "cheekSquint_R", "eyeBlink_L", "eyeBlink_R",
    "eyeLookDown_L", "eyeLookDown_R", "eyeLookIn_L", "eyeLookIn_R", "eyeLookOut_L", "eyeLookOut_R",
    "eyeLookUp_L", "eyeLookUp_R", "eyeSquint_L", "eyeSquint_R", "eyeWide_L", "eyeWide_R", "jawForward",
    "jawLeft", "jawOpen", "jawRight", "mouthClose", "mouthDimple_L", "mouthDimple_R", "mouthFrown_L",
    "mouthFrown_R", "mouthFunnel", "mouthLeft", "mouthLowerDown_L", "mouthLowerDown_R", "mouthPress_L",
    "mouthPress_R", "mouthPucker", "mouthRight", "mouthRollLower", "mouthRollUpper", "mouthShrugLower",
    "mouthShrugUpper", "mouthSmile_L", "mouthSmile_R", "mouthStretch_L", "mouthStretch_R",
    "mouthUpperUp_L", "mouthUpperUp_R", "noseSneer_L", "noseSneer_R",
]
RIG = ICT_SHAPES + [f"identity{k:03d}" for k in range(10)]

# file: (capture fps, rows kept, truncated rows skipped)
FILES = {
    "MySlate_3_Jason_Millers_iPhone.csv": (60.0, 328, 0),
    "S07-001.csv": (30.0, 2028, 0),
    "S88-001.csv": (30.0, 1662, 277),
    "alex_rom_3.csv": (30.0, 4030, 0),
    "alex_rom_4.csv": (30.0, 3809, 0),
    "apfel.csv": (30.0, 1891, 35),
    "facial.csv": (30.0, 1913, 0),
}


@pytest.mark.parametrize("name", sorted(FILES))
def test_real_csvs_parse(data_dir, name):
    fps, rows, skipped = FILES[name]
    curves = livelink.read_livelink_csv(data_dir / "livelink-face" / name, RIG)
    assert curves.fps == fps
    assert curves.skipped_rows == skipped
    assert curves.weights.shape == (rows, 53) and curves.weights.dtype == np.float32
    assert curves.names == ICT_SHAPES
    assert curves.unmapped == ["TongueOut"]
    assert curves.times[0] == 0.0 and np.all(np.diff(curves.times) > 0)
    assert np.median(np.diff(curves.times)) == pytest.approx(1 / fps, rel=2e-3)
    assert curves.weights.min() >= 0.0 and curves.weights.max() <= 1.2
    assert curves.weights.max() > 0.5  # real expressions, not a constant
    # ICT splits BrowInnerUp: both sides carry the same ARKit curve.
    np.testing.assert_array_equal(curves.weights[:, 2], curves.weights[:, 3])


def test_mapping_report():
    header = ["Timecode", "BlendShapeCount", "EyeBlinkLeft", "JawOpen", "JawLeft", "MouthSmileLeft",
              "MouthSmileRight", "BrowInnerUp", "CheekPuff", "TongueOut", "HeadYaw", "LeftEyePitch"]
    mapping, unmapped = livelink.map_arkit_names(header, RIG)
    assert mapping == {
        "EyeBlinkLeft": ("eyeBlink_L",),
        "JawOpen": ("jawOpen",),
        "JawLeft": ("jawLeft",),  # the rig keeps jawLeft whole; not jaw_L
        "MouthSmileLeft": ("mouthSmile_L",),
        "MouthSmileRight": ("mouthSmile_R",),
        "BrowInnerUp": ("browInnerUp_L", "browInnerUp_R"),
        "CheekPuff": ("cheekPuff_L", "cheekPuff_R"),
    }
    assert unmapped == ["TongueOut"]  # head and eye angles are not expression channels
    # A rig named exactly as ARKit maps one to one.
    assert livelink.map_arkit_names(["EyeBlinkLeft"], ["EyeBlinkLeft"])[0] == {"EyeBlinkLeft": ("EyeBlinkLeft",)}


def test_timecodes_to_seconds():
    seconds, rate = livelink.parse_timecodes(["01:02:03:58.5", "01:02:03:59.5", "01:02:04:00.5"], fps=60)
    assert rate == 60.0
    np.testing.assert_allclose(seconds, 3723 + np.array([58.5, 59.5, 60.5]) / 60)
    # Every second frame of a 60 fps timecode (a 30 fps capture): rolls over from 58 to 00.
    codes = [f"00:00:{s:02d}:{f:02d}.250" for s in range(2) for f in range(0, 60, 2)]
    seconds, rate = livelink.parse_timecodes(codes)
    assert rate == 60
    np.testing.assert_allclose(np.diff(seconds), 1 / 30)
    # 25 fps timecode stepping one frame: rollover 24 -> 00.
    seconds, rate = livelink.parse_timecodes([f"10:00:0{s}:{f:02d}" for s in range(2) for f in range(25)])
    assert rate == 25
    np.testing.assert_allclose(np.diff(seconds), 1 / 25)
    # Shorter than a second: the smallest standard rate above the largest frame field.
    assert livelink.parse_timecodes(["00:00:00:27", "00:00:00:28"])[1] == 30
    # Past midnight.
    seconds, _ = livelink.parse_timecodes(["23:59:59:29", "00:00:00:00"], fps=30)
    assert seconds[1] - seconds[0] == pytest.approx(1 / 30)
    with pytest.raises(ValueError, match="not HH:MM:SS:FF.fff"):
        livelink.parse_timecodes(["12:00:00"])
    with pytest.raises(ValueError, match="not below the timecode rate 30"):
        livelink.parse_timecodes(["00:00:00:45"], fps=30)


def _write(tmp_path, lines, name="take.csv"):
    path = tmp_path / name
    path.write_text("\n".join(lines) + "\n")
    return path


def test_truncated_rows_are_skipped_and_counted(tmp_path):
    header = "Timecode,BlendShapeCount,JawOpen,BrowInnerUp,TongueOut,HeadYaw"
    path = _write(tmp_path, [
        header,
        "00:00:00:00.000,3,0.1,0.5,0.0,0.0",
        "00:00:00:02.000,3,0.2,0.6,0.0,0.0",
        "00:00:00:04.000,0",  # tracking lost
        "00:00:00:06.000,3,0.4,0.8,0.0,0.0",
        "00:00:00:08.000,3,0.5,0.9",  # cut short
        "00:00:00:10.000,3,0.6,1.0,0.0,0.0",
    ])
    curves = livelink.read_livelink_csv(path, RIG, timecode_fps=60)
    assert curves.skipped_rows == 2
    assert curves.names == ["browInnerUp_L", "browInnerUp_R", "jawOpen"]
    np.testing.assert_allclose(curves.times, [0, 2 / 60, 6 / 60, 10 / 60])
    np.testing.assert_allclose(curves.weights[:, 2], [0.1, 0.2, 0.4, 0.6], rtol=1e-6)
    np.testing.assert_allclose(curves.weights[:, 0], curves.weights[:, 1])
    assert curves.fps == 30.0 and curves.unmapped == ["TongueOut"]


def test_csv_without_known_channels(tmp_path):
    path = _write(tmp_path, ["Timecode,BlendShapeCount,Foo,Bar", "00:00:00:00.000,2,0.1,0.2", "00:00:00:01.000,2,0.1,0.2"])
    with pytest.raises(InputError) as error:
        livelink.read_livelink_csv(path, RIG)
    message = str(error.value)
    assert message.startswith(f"{path}: no column maps to any of the rig's 63 shapes")
    assert "\n" not in message


def test_bad_inputs_name_the_file(tmp_path):
    with pytest.raises(InputError, match="missing.csv: no such file"):
        livelink.read_livelink_csv(tmp_path / "missing.csv", RIG)
    no_timecode = _write(tmp_path, ["Frame,JawOpen", "0,0.1"], "nt.csv")
    with pytest.raises(InputError, match="nt.csv, line 1: no Timecode column"):
        livelink.read_livelink_csv(no_timecode, RIG)
    bad_code = _write(tmp_path, ["Timecode,JawOpen", "00:00:00:00.0,0.1", "noon,0.2"], "bc.csv")
    with pytest.raises(InputError, match=r"bc.csv, line 3: timecode 'noon' is not"):
        livelink.read_livelink_csv(bad_code, RIG)
    bad_value = _write(tmp_path, ["Timecode,JawOpen", "00:00:00:00.0,0.1", "00:00:00:01.0,high"], "bv.csv")
    with pytest.raises(InputError, match="bv.csv, line 3: expression weights must be numbers"):
        livelink.read_livelink_csv(bad_value, RIG)
    backwards = _write(tmp_path, ["Timecode,JawOpen", "00:00:01:00.0,0.1", "00:00:00:01.0,0.2"], "bw.csv")
    with pytest.raises(InputError, match="bw.csv, line 3: timecode does not increase"):
        livelink.read_livelink_csv(backwards, RIG, timecode_fps=30)


@pytest.mark.parametrize("weight", ["nan", "inf", "-inf", "1e30", "-3"])
def test_weights_must_be_finite_and_near_arkits_range(tmp_path, weight):
    path = _write(tmp_path, ["Timecode,JawOpen", "00:00:00:00.0,0.1", f"00:00:00:01.0,{weight}"])
    with pytest.raises(InputError) as error:
        livelink.read_livelink_csv(path, RIG, timecode_fps=30)
    assert str(error.value) == f"{path}, line 3: expression weights must be finite numbers from -1 to 2 (ARKit's are 0 to 1)"


def test_timecodes_beyond_any_capture_are_refused(tmp_path):
    huge = _write(tmp_path, ["Timecode,JawOpen", "00:00:00:00.0,0.1", "9" * 400 + ":00:00:01.0,0.2"], "huge.csv")
    with pytest.raises(InputError, match="huge.csv, line 3: timecode too large"):
        livelink.read_livelink_csv(huge, RIG, timecode_fps=30)
    dense = _write(tmp_path, ["Timecode,JawOpen", "00:00:00:00.0,0.1", "00:00:00:00.00001,0.2"], "dense.csv")
    with pytest.raises(InputError, match=r"dense.csv: rows come at 3e\+06 per second, not a capture rate \(1 to 1000 fps\)"):
        livelink.read_livelink_csv(dense, RIG, timecode_fps=30)


def test_latin1_and_utf8_with_bom_are_read(tmp_path):
    lines = "Timecode,JawOpen,Remarque\n00:00:00:00.0,0.1,été\n00:00:00:01.0,0.2,hiver\n"
    for name, data in (("latin1.csv", lines.encode("latin-1")), ("bom.csv", lines.encode("utf-8-sig"))):
        path = tmp_path / name
        path.write_bytes(data)
        curves = livelink.read_livelink_csv(path, RIG, timecode_fps=30)
        np.testing.assert_allclose(curves.weights[:, 0], [0.1, 0.2], rtol=1e-6)
        assert curves.unmapped == ["Remarque"]
