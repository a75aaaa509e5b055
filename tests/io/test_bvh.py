"""BVH parsing and forward kinematics, checked by hand and on CMU motion capture."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from facedyn.geometry import quaternion
from facedyn.io import bvh
from facedyn.errors import UsageError
from facedyn.io.errors import InputError
from facedyn import motion

# Root: positions interleaved with a ZXY rotation; Spine: YXZ plus a position channel;
# Head: a single Z rotation; Arm (after the Spine subtree): X rotation and Z position.
TINY = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Zrotation Yposition Xrotation Zposition Yrotation
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 4 Yrotation Xrotation Zrotation Yposition
    JOINT Head
    {
      OFFSET 0 4 1
      CHANNELS 1 Zrotation
      End Site
      {
        OFFSET 0 3 0
      }
    }
  }
  JOINT Arm
  {
    OFFSET 5 8 0
    CHANNELS 2 Xrotation Zposition
    End Site
    {
      OFFSET 0 -6 0
    }
  }
}
MOTION
Frames: 3
Frame Time: 0.0333333
0 0 0 0 0 0   0 0 0 0   0   0 0
1 90 2 0 3 0   90 90 0 2   90   90 7
-4 33 1.5 -21 2 47   12 -58 71 -1.5   -25   40 -3
"""


@pytest.fixture
def tiny(tmp_path):
    path = tmp_path / "tiny.bvh"
    path.write_text(TINY)
    return path


def test_hierarchy_is_parsed(tiny):
    data = bvh.read_bvh(tiny)
    assert data.joint_names == ["Hips", "Spine", "Head", "Arm"]
    assert [j.parent for j in data.joints] == [-1, 0, 1, 0]
    assert [j.first_column for j in data.joints] == [0, 6, 10, 11]
    assert data.joints[1].channels == ("Yrotation", "Xrotation", "Zrotation", "Yposition")
    np.testing.assert_array_equal(data.joints[2].end_site, [0, 3, 0])
    assert data.joints[1].end_site is None
    assert data.values.shape == (3, 13)
    assert data.fps == 30.0  # 0.0333333 is 1/30 rounded by the file


def test_forward_kinematics_matches_a_hand_computation(tiny):
    rotations, positions = bvh.forward_kinematics(bvh.read_bvh(tiny))
    # Frame 1 by hand. Rz90 = [[0,-1,0],[1,0,0],[0,0,1]] takes x to y and y to -x.
    # Hips: at (1, 2, 3) (positions X=1, Y=2, Z=3), R = Rz90 Rx0 Ry0 = Rz90.
    # Spine: Ry90 Rx90 = [[0,1,0],[0,0,-1],[-1,0,0]]; world Rz90 Ry90 Rx90 = [[0,0,1],[0,1,0],[-1,0,0]];
    #   position (1,2,3) + Rz90 (0, 10 + 2, 0) = (1,2,3) + (-12, 0, 0) = (-11, 2, 3).
    # Head: (-11,2,3) + R_spine (0,4,1) = (-11,2,3) + (1, 4, 0) = (-10, 6, 3);
    #   R = R_spine Rz90 = [[0,0,1],[1,0,0],[0,1,0]].
    # Arm: (1,2,3) + Rz90 (5, 8, 0 + 7) = (1,2,3) + (-8, 5, 7) = (-7, 7, 10); R = Rz90 Rx90.
    expected_positions = {0: (1, 2, 3), 1: (-11, 2, 3), 2: (-10, 6, 3), 3: (-7, 7, 10)}
    expected_rotations = {
        0: [[0, -1, 0], [1, 0, 0], [0, 0, 1]],
        1: [[0, 0, 1], [0, 1, 0], [-1, 0, 0]],
        2: [[0, 0, 1], [1, 0, 0], [0, 1, 0]],
        3: [[0, 0, 1], [1, 0, 0], [0, 1, 0]],
    }
    for joint, position in expected_positions.items():
        np.testing.assert_allclose(positions[1, joint], position, atol=1e-12)
        np.testing.assert_allclose(rotations[1, joint], expected_rotations[joint], atol=1e-12)
    # Frame 0 is the rest pose: offsets only, identity rotations.
    np.testing.assert_allclose(positions[0, 2], (0, 14, 1))
    np.testing.assert_allclose(rotations[0], np.broadcast_to(np.eye(3), (4, 3, 3)))


def test_forward_kinematics_matches_scipy_intrinsic_euler(tiny):
    rotations, positions = bvh.forward_kinematics(bvh.read_bvh(tiny))
    # Frame 2 with general angles; scipy's upper-case axes are intrinsic (R = R1 R2 R3).
    hips = Rotation.from_euler("ZXY", [33, -21, 47], degrees=True).as_matrix()
    spine_local = Rotation.from_euler("YXZ", [12, -58, 71], degrees=True).as_matrix()
    head_local = Rotation.from_euler("Z", -25, degrees=True).as_matrix()
    hips_at = np.array([-4, 1.5, 2])
    spine_at = hips_at + hips @ np.array([0, 10 - 1.5, 0])
    head_at = spine_at + hips @ spine_local @ np.array([0, 4, 1])
    np.testing.assert_allclose(positions[2, 1], spine_at, atol=1e-12)
    np.testing.assert_allclose(positions[2, 2], head_at, atol=1e-12)
    np.testing.assert_allclose(rotations[2, 2], hips @ spine_local @ head_local, atol=1e-12)


def test_head_trajectory_scales_and_reexpresses_axes(tiny):
    trajectory = bvh.head_trajectory(tiny, units=2.0)
    assert isinstance(trajectory, motion.SkullTrajectory)
    assert trajectory.fps == 30.0 and trajectory.frame_count == 3
    np.testing.assert_allclose(trajectory.translate[0], (0, 28, 2))
    np.testing.assert_allclose(trajectory.orient[0], (1, 0, 0, 0))
    # A skeleton that faces +X at rest: its forward becomes +Z, its left (-Z here) +X.
    turned = bvh.head_trajectory(tiny, units=1.0, forward="+x")
    np.testing.assert_allclose(turned.translate[0], (-1, 14, 0), atol=1e-12)
    np.testing.assert_allclose(turned.orient[0], (1, 0, 0, 0))
    np.testing.assert_allclose(quaternion.to_matrix(turned.orient[1]),
                               bvh.rest_basis("+x") @ quaternion.to_matrix(trajectory.orient[1]) @ bvh.rest_basis("+x").T,
                               atol=1e-12)
    with pytest.raises(ValueError, match="perpendicular"):
        bvh.rest_basis("+y", "-y")


def test_cmu_skeletons_are_read_in_cmu_units(data_dir):
    found = bvh.conventions(bvh.read_bvh(data_dir / "cmu-mocap" / "131_03.bvh"))
    assert (found.units, found.up, found.forward) == (bvh.CMU_UNIT_CM, "+y", "+z")
    assert "CMU skeleton" in found.how and "toes" in found.how


def test_a_skeleton_without_legs_needs_its_units(tiny):
    """TINY's root is at its feet: no full-body height to read units from."""
    with pytest.raises(InputError, match="cannot tell the units.*set units"):
        bvh.head_trajectory(tiny)


# A standing adult in cm in facedyn's frame (X left, Y up, Z forward): toes 95 cm below the
# root, the head joint 160 cm above the toes, the head's End Site at 178 cm; the root walks
# along +Z 95 cm up, bobbing 2 cm at 2 Hz, turning about the vertical and nodding.
HUMAN = [  # name, parent, offset (cm), channels
    ("Hips", None, (0, 0, 0), "position yaw"),
    ("LeftUpLeg", "Hips", (9, -5, 0), ""), ("LeftLeg", "LeftUpLeg", (0, -42, 0), ""),
    ("LeftFoot", "LeftLeg", (0, -42, 0), ""), ("LeftToe", "LeftFoot", (0, -6, 12), "end"),
    ("RightUpLeg", "Hips", (-9, -5, 0), ""), ("RightLeg", "RightUpLeg", (0, -42, 0), ""),
    ("RightFoot", "RightLeg", (0, -42, 0), ""), ("RightToe", "RightFoot", (0, -6, 12), "end"),
    ("Spine", "Hips", (0, 20, 0), ""), ("Neck", "Spine", (0, 30, 0), ""), ("Head", "Neck", (0, 15, 2), "nod end"),
]


def human_bvh(path, unit_cm=1.0, up="+y", forward="+z", frames=240, fps=120.0, bob_cm=2.0):
    """HUMAN written in `unit_cm` per unit along the given file axes (left is +x for both
    conventions used here, so the nod is an Xrotation; the yaw turns about `up`)."""
    to_file = bvh.rest_basis(forward, up).T  # facedyn -> file axes
    yaw_channel = {"+y": "Yrotation", "+z": "Zrotation"}[up]
    t = np.arange(frames) / fps
    root = np.stack([np.zeros_like(t), 95 + bob_cm * np.sin(2 * np.pi * 2 * t), 130 * t], axis=1) @ to_file.T / unit_cm
    yaw, nod = 30 * np.sin(2 * np.pi * 0.5 * t), 10 * np.sin(2 * np.pi * 1.5 * t)
    columns, text = [], ["HIERARCHY"]

    def block(name, indent):
        _, _, offset, channels = next(j for j in HUMAN if j[0] == name)
        pad = "  " * indent
        text.append(f"{pad}{'ROOT' if indent == 0 else 'JOINT'} {name}")
        text.append(f"{pad}{{")
        text.append(f"{pad}  OFFSET " + " ".join(f"{v:.6f}" for v in to_file @ np.array(offset, float) / unit_cm))
        wanted = []
        if "position" in channels:
            wanted += ["Xposition", "Yposition", "Zposition"]
            columns.extend(root.T)
        if "yaw" in channels:
            wanted.append(yaw_channel)
            columns.append(yaw)
        if "nod" in channels:
            wanted.append("Xrotation")
            columns.append(nod)
        if wanted:
            text.append(f"{pad}  CHANNELS {len(wanted)} " + " ".join(wanted))
        for child in [j[0] for j in HUMAN if j[1] == name]:
            block(child, indent + 1)
        if "end" in channels:
            tip = (0, 0, 5) if "Toe" in name else (0, 18, 0)
            text.append(f"{pad}  End Site\n{pad}  {{\n{pad}    OFFSET " + " ".join(f"{v:.6f}" for v in to_file @ np.array(tip, float) / unit_cm) + f"\n{pad}  }}")
        text.append(f"{pad}}}")

    block("Hips", 0)
    text += ["MOTION", f"Frames: {frames}", f"Frame Time: {1 / fps:.7f}"]
    text += [" ".join(f"{v:.6f}" for v in row) for row in np.stack(columns, axis=1)]
    path.write_text("\n".join(text) + "\n")
    return path


@pytest.mark.parametrize(
    "unit_cm, up, forward, unit_name",
    [(1.0, "+y", "+z", "cm"), (0.1, "+y", "+z", "mm"), (2.54, "+z", "-y", "inch"), (100.0, "+z", "-y", "m")],
)
def test_units_and_axes_come_from_the_skeleton(tmp_path, unit_cm, up, forward, unit_name):
    reference = bvh.head_trajectory(human_bvh(tmp_path / "cm.bvh"), units=1.0, up="+y", forward="+z")
    path = human_bvh(tmp_path / "other.bvh", unit_cm, up, forward)
    found = bvh.conventions(bvh.read_bvh(path))
    assert (found.units, found.up, found.forward) == (unit_cm, up, forward)
    assert f"skeleton height 178 cm in {unit_name}" in found.how and "toes" in found.how
    trajectory = bvh.head_trajectory(path)
    np.testing.assert_allclose(trajectory.translate, reference.translate, atol=1e-3)
    np.testing.assert_allclose(np.abs(np.sum(trajectory.orient * reference.orient, axis=1)), 1.0, atol=1e-9)
    # Frame 0: no yaw or nod, the root at 95 cm: the head joint is 160 cm up, facing +Z.
    np.testing.assert_allclose(reference.translate[0], (0, 160, 2), atol=1e-4)
    np.testing.assert_allclose(reference.orient[0], (1, 0, 0, 0), atol=1e-9)


def test_arguments_override_what_the_file_says(tmp_path):
    path = human_bvh(tmp_path / "mm.bvh", unit_cm=0.1)
    given = bvh.conventions(bvh.read_bvh(path), units=0.1, up="+y", forward="+z")
    assert given.how == "all given"
    with pytest.raises(UsageError, match="positive number of cm per BVH unit"):
        bvh.head_trajectory(path, units=-1.0)
    with pytest.raises(UsageError, match="up axis must be one of"):
        bvh.head_trajectory(path, up="y")
    with pytest.raises(UsageError, match="perpendicular"):
        bvh.head_trajectory(path, up="+y", forward="-y")
    with pytest.raises(InputError, match=r"mm.bvh: BVH forward axis '\+y' and up axis '\+y' must be perpendicular \(up \+y: root to Head\)"):
        bvh.head_trajectory(path, forward="+y")


def test_a_head_far_above_the_floor_names_what_to_set(tmp_path):
    """A cm skeleton read as CMU units: its head 162 cm over its lowest toe (160 cm, plus the
    2 cm bob the floor is measured at) becomes 9.1 m."""
    path = human_bvh(tmp_path / "cm.bvh")
    with pytest.raises(InputError) as error:
        bvh.head_trajectory(path, units=bvh.CMU_UNIT_CM)
    message = str(error.value)
    assert message.startswith(f"{path}: Head is 9.1 m above the skeleton's lowest point at 5.64 cm per BVH unit")
    assert "set units (cm per BVH unit)" in message and "\n" not in message


def test_sustained_accelerations_of_several_g_are_refused(tmp_path):
    """A head alone (no floor to measure from) bobbing 3 cm at 3 Hz: 0.7 g on average over
    a second in cm, 3.9 g when its units are taken for CMU's."""
    t = np.arange(360) / 120.0
    rows = "\n".join(f"0 {150 + 3 * np.sin(2 * np.pi * 3 * x):.6f} 0" for x in t)
    path = tmp_path / "head.bvh"
    path.write_text(f"HIERARCHY\nROOT Head\n{{\n OFFSET 0 0 0\n CHANNELS 3 Xposition Yposition Zposition\n}}\n"
                    f"MOTION\nFrames: {len(t)}\nFrame Time: 0.0083333\n{rows}\n")
    real = bvh.head_trajectory(path, units=1.0, up="+y", forward="+z")
    assert 0.6 < bvh.sustained_acceleration_g(real.translate, real.fps) < 0.75  # 2/pi of the 1.09 g peak, less the 50 ms step's attenuation
    with pytest.raises(InputError, match=r"head.bvh: Head accelerates at 3\.\d g on average over a second at 5.64 cm per BVH unit.*set units"):
        bvh.head_trajectory(path, units=bvh.CMU_UNIT_CM, up="+y", forward="+z")
    with pytest.raises(InputError, match="cannot tell which axis is up: Head is the root; set up"):
        bvh.head_trajectory(path)


@pytest.mark.parametrize(
    "old, new, line, reason",
    [
        ("OFFSET 0 4 1", "OFFSET 0 four 1", 12, "expected an OFFSET value, got 'four'"),
        ("CHANNELS 1 Zrotation", "CHANNELS 1 Zrotate", 13, "unknown channel 'Zrotate'"),
        ("  JOINT Arm", "  JIONT Arm", 20, "expected JOINT, End Site or '}', got 'JIONT'"),
        ("Frames: 3", "Frames: 4", 31, "header says 4 frames but the file has 3"),
        ("90 7\n", "90 x\n", 34, "channel values must be numbers"),
        ("-4 33 1.5", "-4 33", 35, "expected 13 channel values, got 12"),
    ],
    ids=["offset", "channel", "keyword", "frames", "value", "count"],
)
def test_malformed_files_name_file_and_line(tmp_path, old, new, line, reason):
    path = tmp_path / "bad.bvh"
    path.write_text(TINY.replace(old, new))
    with pytest.raises(InputError) as error:
        bvh.read_bvh(path)
    assert str(error.value) == f"{path}, line {line}: {reason}"


def test_missing_file_and_missing_sections(tmp_path):
    with pytest.raises(InputError, match="nothing.bvh: no such file"):
        bvh.read_bvh(tmp_path / "nothing.bvh")
    path = tmp_path / "cut.bvh"
    path.write_text(TINY.split("MOTION")[0])
    with pytest.raises(InputError, match="cut.bvh: no MOTION section"):
        bvh.read_bvh(path)


def test_unknown_joint_lists_the_joints(tiny):
    with pytest.raises(InputError) as error:
        bvh.head_trajectory(tiny, joint="Skull")
    assert str(error.value) == f"{tiny}: no joint named 'Skull'; joints: Hips, Spine, Head, Arm"
    assert "\n" not in str(error.value)


def test_cmu_hop_head_acceleration_is_about_one_g(data_dir):
    trajectory = bvh.head_trajectory(data_dir / "cmu-mocap" / "131_03.bvh")
    assert trajectory.fps == 120.0 and trajectory.frame_count == 1102
    accel = np.linalg.norm(motion.accelerations(trajectory).linear_acceleration_world, axis=1) / motion.G_CM_S2
    p95 = np.percentile(accel, 95)
    assert 0.8 < p95 < 1.4, p95
    height = trajectory.translate[:, 1]
    assert 110 < np.median(height) < 160  # the top of the neck of a standing adult, cm


def test_cmu_walk_speed_and_facing(data_dir):
    trajectory = bvh.head_trajectory(data_dir / "cmu-mocap" / "131_01.bvh")
    velocity = np.gradient(trajectory.translate, 1 / trajectory.fps, axis=0)
    horizontal = np.linalg.norm(velocity[:, [0, 2]], axis=1)
    assert 0.7 < np.percentile(horizontal, 90) / 100 < 1.6  # m/s
    # CMU performers face +Z at rest and walk along +Z here: the skull's +Z faces the walk.
    moving = horizontal > 50
    forward = quaternion.rotate(trajectory.orient[moving], [0.0, 0.0, 1.0])
    cosine = np.sum(forward[:, [0, 2]] * velocity[moving][:, [0, 2]], axis=1) / (
        np.linalg.norm(forward[:, [0, 2]], axis=1) * horizontal[moving]
    )
    assert np.median(cosine) > 0.5
    up = quaternion.rotate(trajectory.orient, [0.0, 1.0, 0.0])
    assert np.median(up[:, 1]) > 0.9  # upright
    assert np.all(np.sum(trajectory.orient[1:] * trajectory.orient[:-1], axis=1) > 0)  # continuous


@pytest.mark.parametrize("value", ["nan", "inf", "-inf", "1e308", "-2e6"])
def test_channel_and_offset_values_must_be_finite_and_bounded(tmp_path, value):
    path = tmp_path / "bad.bvh"
    path.write_text(TINY.replace("-4 33 1.5", f"-4 {value} 1.5"))
    with pytest.raises(InputError) as error:
        bvh.read_bvh(path)
    assert str(error.value) == f"{path}, line 35: channel values must be finite numbers within ±1e+06"
    path.write_text(TINY.replace("OFFSET 0 4 1", f"OFFSET 0 {value} 1"))
    with pytest.raises(InputError, match=f"line 12: an OFFSET value '{value}' is not a finite number within ±1e\\+06"):
        bvh.read_bvh(path)


@pytest.mark.parametrize("frame_time", ["nan", "inf", "-0.01", "0", "1e6", "1e-300"])
def test_frame_time_must_be_a_plausible_number_of_seconds(tmp_path, frame_time):
    path = tmp_path / "bad.bvh"
    path.write_text(TINY.replace("Frame Time: 0.0333333", f"Frame Time: {frame_time}"))
    with pytest.raises(InputError, match=r"bad.bvh, line 32: Frame Time must be 0.0001 to 10 seconds \(0.1 to 10000 fps\)"):
        bvh.read_bvh(path)


def test_thousands_of_nested_joints_parse_without_recursion(tmp_path):
    depth = 3000
    opening = "".join(f"JOINT J{i}\n{{\nOFFSET 0 1 0\nCHANNELS 1 Xrotation\n" for i in range(1, depth))
    text = f"HIERARCHY\nROOT J0\n{{\nOFFSET 0 0 0\nCHANNELS 1 Xrotation\n{opening}" + "}\n" * depth
    angles = np.full(depth, 0.01)
    path = tmp_path / "deep.bvh"
    path.write_text(text + "MOTION\nFrames: 2\nFrame Time: 0.01\n" + "0 " * depth + "\n" + " ".join(map(str, angles)) + "\n")
    data = bvh.read_bvh(path)
    assert len(data.joints) == depth and data.joints[-1].parent == depth - 2
    rotations, positions = bvh.forward_kinematics(data)
    np.testing.assert_allclose(positions[0, -1], (0, depth - 1, 0))
    # Frame 1: joint k is rotated by 0.01 k degrees about X, so the chain bends in the YZ plane.
    bend = np.radians(0.01 * np.arange(1, depth))
    np.testing.assert_allclose(positions[1, -1], (0, np.cos(bend).sum(), np.sin(bend).sum()), rtol=1e-9)
    with pytest.raises(InputError, match=r"no joint named 'Head'; joints: J0, J1, .*, J39, \.\.\. \(3000 joints\)$"):
        data.joint_index("Head")
    cut = tmp_path / "cut.bvh"
    cut.write_text(text.split("}")[0] + "MOTION\nFrames: 1\nFrame Time: 0.01\n0\n")  # no block closed
    with pytest.raises(InputError, match="hierarchy ends where JOINT, End Site or '}' was expected"):
        bvh.read_bvh(cut)


def test_latin1_files_are_read(tmp_path):
    path = tmp_path / "latin1.bvh"
    path.write_bytes(TINY.replace("Arm", "Épaule").encode("latin-1"))
    assert bvh.read_bvh(path).joint_names == ["Hips", "Spine", "Head", "Épaule"]
    path.write_bytes(TINY.replace("Arm", "Épaule").encode("utf-8"))
    assert bvh.read_bvh(path).joint_names[-1] == "Épaule"


def test_other_files_are_not_bvh(tmp_path):
    path = tmp_path / "passwd"
    path.write_text("root:x:0:0:root:/root:/bin/bash\ndaemon:x:1:1:daemon:/usr/sbin:/usr/sbin/nologin\n")
    with pytest.raises(InputError) as error:
        bvh.head_trajectory(path)
    assert str(error.value) == f"{path}, line 1: not a BVH file: it does not start with HIERARCHY"
