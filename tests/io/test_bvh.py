"""BVH parsing and forward kinematics, checked by hand and on CMU motion capture."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from facedyn.geometry import quaternion
from facedyn.io import bvh
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
    trajectory = bvh.head_trajectory(tiny, units_to_cm=2.0)
    assert isinstance(trajectory, motion.SkullTrajectory)
    assert trajectory.fps == 30.0 and trajectory.frame_count == 3
    np.testing.assert_allclose(trajectory.translate[0], (0, 28, 2))
    np.testing.assert_allclose(trajectory.orient[0], (1, 0, 0, 0))
    # A skeleton that faces +X at rest: its forward becomes +Z, its left (-Z here) +X.
    turned = bvh.head_trajectory(tiny, units_to_cm=1.0, rest_forward="+x")
    np.testing.assert_allclose(turned.translate[0], (-1, 14, 0), atol=1e-12)
    np.testing.assert_allclose(turned.orient[0], (1, 0, 0, 0))
    np.testing.assert_allclose(quaternion.to_matrix(turned.orient[1]),
                               bvh.rest_basis("+x") @ quaternion.to_matrix(trajectory.orient[1]) @ bvh.rest_basis("+x").T,
                               atol=1e-12)
    with pytest.raises(ValueError, match="perpendicular"):
        bvh.rest_basis("+y", "-y")


def test_cmu_default_scale_is_cmu_units(tiny):
    default = bvh.head_trajectory(tiny)
    np.testing.assert_allclose(default.translate[0], (0, 14 * bvh.CMU_UNIT_CM, bvh.CMU_UNIT_CM))


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
