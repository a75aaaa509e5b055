"""H's skull-motion input: landmark accelerations against their formula, windows, validation."""
import numpy as np
import pytest

from facedyn.dynamics.features import skull_velocities, span_windows, windows
from facedyn.dynamics.skull_motion import PAPER, SkullMotionInput, skull_accelerations
from facedyn.geometry import quaternion

FPS = 120.0
LANDMARKS = np.array([[0.0, 8.0, 5.0], [-6.0, 2.0, 4.0], [6.0, 2.0, 4.0], [0.0, -6.0, 6.0], [0.0, 0.0, -8.0]])


def fixed_heading(frames: int, yaw_deg: float) -> np.ndarray:
    return np.repeat(quaternion.from_rotvec(np.array([0.0, np.radians(yaw_deg), 0.0]))[None], frames, axis=0)


def test_constant_travel_is_no_load_whatever_the_heading():
    """Galilean invariance: a skull travelling at a steady 130 cm/s has zero acceleration in
    any heading, while the paper's skull-frame velocities depend on the heading."""
    frames = 40
    translate = np.arange(frames)[:, None] / FPS * np.array([0.0, 0.0, 130.0])
    for yaw in (0.0, 60.0, 135.0):
        orient = fixed_heading(frames, yaw)
        np.testing.assert_allclose(skull_accelerations(translate, orient, LANDMARKS, FPS), 0.0, atol=1e-9)
    v0 = skull_velocities(translate, fixed_heading(frames, 0.0), LANDMARKS, FPS)[5:]
    v60 = skull_velocities(translate, fixed_heading(frames, 60.0), LANDMARKS, FPS)[5:]
    assert np.abs(v0 - v60).max() > 100.0


def test_a_steady_acceleration_reads_as_itself_in_skull_axes_and_zero_at_the_ends():
    frames = 30
    a = np.array([50.0, -981.0, 20.0])
    time = np.arange(frames) / FPS
    translate = 0.5 * time[:, None] ** 2 * a
    orient = fixed_heading(frames, 40.0)
    got = skull_accelerations(translate, orient, LANDMARKS, FPS)
    expected = quaternion.rotate(quaternion.conjugate(orient[0]), a)
    np.testing.assert_allclose(got[1:-1], np.broadcast_to(expected, got[1:-1].shape), rtol=1e-9, atol=1e-6)
    assert np.all(got[[0, -1]] == 0)


def test_a_steady_spin_gives_the_centripetal_acceleration():
    """Spinning at omega about the skull's y axis: omega x (omega x b) in skull axes, to the
    second difference's accuracy (a relative error of (omega dt)^2 / 12)."""
    frames, omega = 50, 4.0  # rad/s
    angles = omega * np.arange(frames) / FPS
    orient = quaternion.from_rotvec(angles[:, None] * np.array([0.0, 1.0, 0.0]))
    got = skull_accelerations(np.zeros((frames, 3)), orient, LANDMARKS, FPS)
    w = np.array([0.0, omega, 0.0])
    expected = np.cross(w, np.cross(w, LANDMARKS))
    np.testing.assert_allclose(got[1:-1], np.broadcast_to(expected, got[1:-1].shape), rtol=1e-3, atol=1e-3)


def test_span_windows_reads_past_and_future_with_zeros_outside():
    values = np.arange(1, 6, dtype=np.float32)[:, None, None] * np.ones((5, 2, 3), np.float32)  # frame k holds k + 1
    w = span_windows(values, 2, 1).reshape(5, 2, 4, 3)
    np.testing.assert_array_equal(w[0, 0, :, 0], [0, 0, 1, 2])
    np.testing.assert_array_equal(w[2, 1, :, 0], [1, 2, 3, 4])
    np.testing.assert_array_equal(w[4, 0, :, 0], [3, 4, 5, 0])
    np.testing.assert_array_equal(windows(values, 2), span_windows(values, 2, 2))


def test_the_papers_input_is_exactly_b_of_t():
    rng = np.random.default_rng(1)
    translate = np.cumsum(rng.normal(0, 0.5, (25, 3)), axis=0)
    orient = quaternion.from_rotvec(np.cumsum(rng.normal(0, 0.02, (25, 3)), axis=0))
    got = PAPER.features(translate, orient, LANDMARKS, FPS)
    b = windows(skull_velocities(translate, orient, LANDMARKS, FPS).astype(np.float32), 10).reshape(25, -1)
    np.testing.assert_array_equal(got, b)
    default = SkullMotionInput().features(translate, orient, LANDMARKS, FPS)
    assert default.shape == (25, 5 * 41 * 3) and default.dtype == np.float32


def test_settings_are_checked_and_round_trip():
    assert SkullMotionInput.from_json(SkullMotionInput("velocity", 4, 2).to_json()) == SkullMotionInput("velocity", 4, 2)
    with pytest.raises(ValueError, match="one of"):
        SkullMotionInput("jerk")
    with pytest.raises(ValueError, match="past"):
        SkullMotionInput("acceleration", -1, 10)
