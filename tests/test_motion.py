"""Skull motion sources: magnitudes and frequencies, ramps, resampling, derivatives."""
from pathlib import Path

import numpy as np
import pytest

from facedyn.geometry import quaternion
from facedyn import motion

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
G = motion.G_CM_S2


def _vertical_g(trajectory):
    return motion.accelerations(trajectory).linear_acceleration_world[:, 1] / G


def _dominant_hz(signal, fps, above_hz=0.5):
    signal = signal - signal.mean()
    spectrum = np.abs(np.fft.rfft(signal * np.hanning(len(signal))))
    freqs = np.fft.rfftfreq(len(signal), 1 / fps)
    band = freqs > above_hz
    return freqs[band][np.argmax(spectrum[band])]


def test_trajectory_validates_and_is_read_only():
    trajectory = motion.SkullTrajectory(np.zeros((3, 3)), quaternion.identity((3,)), 100)
    assert trajectory.frame_count == 3 and trajectory.fps == 100.0
    np.testing.assert_allclose(trajectory.times, [0, 0.01, 0.02])
    with pytest.raises(ValueError, match="read-only"):
        trajectory.translate[0, 0] = 1.0
    with pytest.raises(ValueError, match="translate must be"):
        motion.SkullTrajectory(np.zeros((3, 2)), quaternion.identity((3,)), 100)
    with pytest.raises(ValueError, match="orient must be"):
        motion.SkullTrajectory(np.zeros((3, 3)), quaternion.identity((2,)), 100)
    with pytest.raises(ValueError, match="unit quaternions"):
        motion.SkullTrajectory(np.zeros((1, 3)), [[2.0, 0, 0, 0]], 100)
    with pytest.raises(ValueError, match="fps must be positive"):
        motion.SkullTrajectory(np.zeros((1, 3)), quaternion.identity((1,)), 0)


@pytest.mark.parametrize(
    "source, step_hz, low_g, high_g",
    [(motion.walk, 2.0, 0.3, 0.5), (motion.run, 2.8, 0.9, 1.25), (motion.hop, 2.0, 1.0, 1.5)],
    ids=["walk", "run", "hop"],
)
def test_gaits_have_realistic_accelerations(source, step_hz, low_g, high_g):
    peaks = []
    for seed in range(3):
        trajectory = source(6.0, 120.0, seed)
        vertical = _vertical_g(trajectory)
        peaks.append(np.abs(vertical).max())
        assert _dominant_hz(trajectory.translate[:, 1], 120.0) == pytest.approx(step_hz, abs=0.2)
        assert trajectory.translate[-1, 2] > trajectory.translate[0, 2]  # advances along +Z
        angles = np.degrees(quaternion.angle_between(quaternion.identity((1,)), trajectory.orient))
        look = {motion.walk: 60.0, motion.run: 30.0, motion.hop: 90.0}[source]
        assert 0.3 * look < angles.max() < 1.1 * look + 8  # the head looks around, within its range
        speed = np.degrees(np.linalg.norm(motion.accelerations(trajectory).angular_velocity_world, axis=1))
        assert 50 < np.percentile(speed, 95) and speed.max() < motion.LOOK_MAX_DEG_S + 30  # as fast as real mocap, no faster
    assert low_g <= min(peaks) and max(peaks) <= high_g, peaks
    assert len(set(np.round(peaks, 6))) == 3  # seeds give different takes


def test_flight_gaits_fall_freely_and_land_hard():
    run = _vertical_g(motion.run(6.0, 120.0, 0))
    assert run.min() == pytest.approx(-1.0, abs=0.1)  # the flight phase
    hop = _vertical_g(motion.hop(6.0, 120.0, 0))
    assert 1.0 <= hop.max() <= 1.5  # landing spikes
    assert np.mean(hop < -0.9) > 0.3  # a large part of each hop is in the air


def test_gaits_without_looking_around_keep_small_rotations():
    for source in (motion.walk, motion.run, motion.hop):
        trajectory = source(6.0, 120.0, 1, look_deg=0.0)
        angles = np.degrees(quaternion.angle_between(quaternion.identity((1,)), trajectory.orient))
        assert 0.5 < angles.max() < 8
    with pytest.raises(ValueError, match="look_deg"):
        motion.walk(2.0, 120.0, 0, look_deg=-5.0)


def test_walk_speed_and_seed_determinism():
    a, b = motion.walk(4.0, 100.0, seed=7), motion.walk(4.0, 100.0, seed=7)
    np.testing.assert_array_equal(a.translate, b.translate)
    np.testing.assert_array_equal(a.orient, b.orient)
    assert a.frame_count == 400
    speed = (a.translate[-1, 2] - a.translate[0, 2]) / (a.times[-1])
    assert speed == pytest.approx(130.0, rel=0.1)
    assert 3.0 < np.ptp(a.translate[:, 1]) < 6.0  # 4-5 cm head bob
    assert not np.array_equal(motion.walk(4.0, 100.0, seed=8).translate, a.translate)


@pytest.mark.parametrize("freq_hz", [6.0, 8.5, 11.0])
def test_platform_frequency_is_detected(freq_hz):
    trajectory = motion.platform(freq_hz, 0.3, duration_s=4.0, fps=120.0, seed=1)
    assert _dominant_hz(trajectory.translate[:, 1], 120.0) == pytest.approx(freq_hz, abs=0.25)
    assert np.ptp(trajectory.translate[:, 1]) == pytest.approx(0.6, rel=0.02)
    assert np.abs(trajectory.translate[:, [0, 2]]).max() < 0.1 * 0.3  # small horizontal motion
    peak = np.abs(_vertical_g(trajectory)).max()
    assert peak == pytest.approx(0.3 * (2 * np.pi * freq_hz) ** 2 / G, rel=0.1)


@pytest.mark.parametrize("axis", ["side", "forward"])
def test_a_platform_shakes_along_the_axis_it_is_given(axis):
    """A horizontal platform carries the same sinusoid along its axis; vertical stays the default, unchanged."""
    index = motion.PLATFORM_AXES[axis]
    trajectory = motion.platform(7.0, 0.4, duration_s=4.0, fps=120.0, seed=1, axis=axis)
    assert _dominant_hz(trajectory.translate[:, index], 120.0) == pytest.approx(7.0, abs=0.25)
    assert np.ptp(trajectory.translate[:, index]) == pytest.approx(0.8, rel=0.02)
    assert np.abs(np.delete(trajectory.translate, index, axis=1)).max() < 0.1 * 0.4
    default, up = (motion.platform(7.0, 0.4, duration_s=1.0, seed=3, **kw) for kw in ({}, {"axis": "up"}))
    assert np.array_equal(default.translate, up.translate) and np.array_equal(default.orient, up.orient)
    assert motion.parse_platform("4hz:Side") == (4.0, "side") and motion.parse_platform("9") == (9.0, "up")
    for bad, message in (("4hz:down", "one of side, up, forward"), ("fast", "needs a frequency")):
        with pytest.raises(ValueError, match=message):
            motion.parse_platform(bad)
    with pytest.raises(ValueError, match="one of side, up, forward"):
        motion.platform(7.0, 0.4, axis="diagonal")


@pytest.mark.parametrize(
    "freq_hz, amplitude_cm, fps, message",
    [(0.0, 0.3, 120, "frequency must be positive"), (-6.0, 0.3, 120, "frequency must be positive"),
     (8.0, -0.1, 120, "amplitude must be >= 0"), (40.0, 0.3, 60, "needs fps above 80")],
)
def test_platform_rejects_bad_parameters(freq_hz, amplitude_cm, fps, message):
    with pytest.raises(ValueError, match=message):
        motion.platform(freq_hz, amplitude_cm, fps=fps)


def test_still_and_sway():
    still = motion.still(2.0, 60.0)
    assert still.frame_count == 120
    assert not still.translate.any() and np.all(still.orient == quaternion.identity((120,)))
    kinematics = motion.accelerations(still)
    assert not kinematics.linear_acceleration_world.any() and not kinematics.angular_velocity_world.any()
    sway = motion.still(10.0, 60.0, seed=2, sway_cm=1.0)
    assert 0.2 < np.abs(sway.translate).max() <= 1.0
    assert np.abs(_vertical_g(sway)).max() < 0.01


@pytest.mark.parametrize("source", [motion.walk, motion.run, motion.hop, lambda *a, **k: motion.platform(9.0, 0.3, *a, **k)],
                         ids=["walk", "run", "hop", "platform"])
def test_motion_starts_and_stops_smoothly(source):
    ramp = motion.Ramp(in_s=0.5, out_s=0.5, before_s=0.5, after_s=1.0)
    trajectory = source(4.0, 120.0, 0, ramp=ramp)
    before, after = slice(0, 60), slice(int(3.0 * 120), None)
    for part in (before, after):
        np.testing.assert_allclose(trajectory.translate[part], trajectory.translate[part][:1].repeat(len(trajectory.translate[part]), 0))
        np.testing.assert_allclose(trajectory.orient[part], quaternion.identity((len(trajectory.orient[part]),)), atol=1e-15)
    kinematics = motion.accelerations(trajectory)
    assert np.abs(kinematics.linear_acceleration_world[after][1:]).max() < 1e-6  # nothing moves once stopped
    vertical = np.abs(kinematics.linear_acceleration_world[:, 1])
    assert vertical[60:72].max() < 0.25 * vertical[150:330].max()  # the first 0.1 s of the fade-in is gentle


def test_ramp_longer_than_motion_is_refused():
    with pytest.raises(ValueError, match="longer than"):
        motion.walk(1.0, ramp=motion.Ramp(in_s=0.6, out_s=0.6))


def test_resample_translation_and_rotation():
    fps = 30.0
    times = np.arange(31) / fps
    translate = np.stack([times**3, 2 * times, np.sin(times)], axis=1)
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    orient = quaternion.from_axis_angle(np.broadcast_to(axis, (31, 3)), 1.5 * times)  # constant angular velocity
    trajectory = motion.SkullTrajectory(translate, orient, fps)
    for method, tolerance in (("cubic", 1e-4), ("linear", 2e-3)):
        out = motion.resample(trajectory, 120.0, method=method)
        assert out.fps == 120.0 and out.frame_count == 121
        expected = np.stack([out.times**3, 2 * out.times, np.sin(out.times)], axis=1)
        np.testing.assert_allclose(out.translate, expected, atol=tolerance)
        # slerp between samples of a constant-velocity rotation is exact
        truth = quaternion.from_axis_angle(np.broadcast_to(axis, (121, 3)), 1.5 * out.times)
        np.testing.assert_allclose(quaternion.angle_between(out.orient, truth), 0.0, atol=1e-6)
    down = motion.resample(trajectory, 10.0)
    np.testing.assert_allclose(down.translate, translate[::3], atol=1e-12)
    with pytest.raises(ValueError, match="method"):
        motion.resample(trajectory, 60.0, method="nearest")


def test_accelerations_of_known_motion():
    fps, omega_hz, amplitude = 240.0, 2.0, 3.0
    times = np.arange(480) / fps
    w = 2 * np.pi * omega_hz
    translate = np.stack([np.zeros_like(times), amplitude * np.sin(w * times), 50.0 * times], axis=1)
    # A nod (about skull X) of 0.1 sin(w t) on top of a fixed 90 degree yaw about world Y.
    yaw = quaternion.from_axis_angle(np.array([0.0, 1.0, 0.0]), np.pi / 2)
    nod = quaternion.from_axis_angle(np.broadcast_to([1.0, 0.0, 0.0], (480, 3)), 0.1 * np.sin(w * times))
    orient = quaternion.multiply(np.broadcast_to(yaw, (480, 4)), nod)
    k = motion.accelerations(motion.SkullTrajectory(translate, orient, fps))
    inner = slice(2, -2)
    expected = np.stack([np.zeros_like(times), -amplitude * w**2 * np.sin(w * times), np.zeros_like(times)], axis=1)
    np.testing.assert_allclose(k.linear_acceleration_world[inner], expected[inner], atol=0.01 * amplitude * w**2)
    # Nodding about skull X: in the skull frame the angular velocity is along X ...
    rate = 0.1 * w * np.cos(w * times)
    np.testing.assert_allclose(k.angular_velocity_skull[inner, 0], rate[inner], atol=0.01 * 0.1 * w)
    np.testing.assert_allclose(k.angular_velocity_skull[inner, 1:], 0.0, atol=1e-9)
    # ... and in the world, after the 90 degree yaw, skull X is world -Z.
    np.testing.assert_allclose(k.angular_velocity_world[inner, 2], -rate[inner], atol=0.01 * 0.1 * w)
    np.testing.assert_allclose(k.angular_acceleration_skull[inner, 0], -0.1 * w**2 * np.sin(w * times)[inner],
                               atol=0.02 * 0.1 * w**2)
    # Seen from the skull, the vertical bob tilts with the nod: Rx(theta)^T (0, a, 0) = (0, a cos, -a sin).
    theta = 0.1 * np.sin(w * times)
    a_y = k.linear_acceleration_world[:, 1]
    np.testing.assert_allclose(k.linear_acceleration_skull[:, 1], a_y * np.cos(theta), atol=1e-9)
    np.testing.assert_allclose(k.linear_acceleration_skull[:, 2], -a_y * np.sin(theta), atol=1e-9)
    np.testing.assert_allclose(k.linear_acceleration_skull[:, 0], 0.0, atol=1e-6)
    with pytest.raises(ValueError, match="at least 3 frames"):
        motion.accelerations(motion.SkullTrajectory(np.zeros((2, 3)), quaternion.identity((2,)), fps))


@pytest.mark.skipif(not DATA.is_dir(), reason=f"shared data folder {DATA} is absent")
def test_from_bvh_windows_and_resamples():
    path = DATA / "cmu-mocap" / "131_03.bvh"
    whole = motion.from_bvh(path)
    assert whole.fps == 120.0 and whole.frame_count == 1102
    window = motion.from_bvh(path, duration_s=2.0, seed=4)
    assert window.frame_count == 240
    start = np.flatnonzero(np.all(whole.translate == window.translate[0], axis=1))
    assert len(start) == 1 and start[0] > 0
    np.testing.assert_array_equal(window.translate, whole.translate[start[0] : start[0] + 240])
    again = motion.from_bvh(path, duration_s=2.0, seed=4)
    np.testing.assert_array_equal(again.translate, window.translate)
    slow = motion.from_bvh(path, duration_s=3.0, fps=96.0)
    assert slow.fps == 96.0 and slow.frame_count == 288
    np.testing.assert_allclose(slow.translate[0], whole.translate[0])
    with pytest.raises(ValueError, match="asked for 60"):
        motion.from_bvh(path, duration_s=60)


def test_lowpass_keeps_gait_and_removes_jitter():
    from facedyn.motion import lowpass

    walking = motion.walk(duration_s=3.0, fps=120.0, seed=1)
    smoothed = lowpass(walking, 10.0)
    np.testing.assert_allclose(smoothed.translate[30:-30], walking.translate[30:-30], atol=0.02)
    rng = np.random.default_rng(0)
    jittery = motion.SkullTrajectory(walking.translate + rng.normal(scale=0.05, size=walking.translate.shape), walking.orient, 120.0)
    raw = np.linalg.norm(motion.accelerations(jittery).linear_acceleration_world, axis=1)
    filtered = np.linalg.norm(motion.accelerations(lowpass(jittery, 10.0)).linear_acceleration_world, axis=1)
    assert np.percentile(filtered, 95) < 0.3 * np.percentile(raw, 95)
    with pytest.raises(ValueError, match="cutoff"):
        lowpass(walking, 80.0)


@pytest.mark.parametrize("source", [motion.walk, motion.run, motion.hop, motion.dance, motion.turn, motion.jump],
                         ids=["walk", "run", "hop", "dance", "turn", "jump"])
def test_impacts_add_short_jolts_near_the_tissue_resonance(source):
    """Foot contacts ring the head at 6-16 Hz for a cycle or two: a few tenths of a g to about a g,
    millimetres of travel, continuous accelerations, the gait itself unchanged."""
    smooth, jolted = source(6.0, 120.0, 3), source(6.0, 120.0, 3, impacts=True)
    assert smooth.frame_count == jolted.frame_count
    jolt = jolted.translate - smooth.translate
    assert 0.01 < np.abs(jolt).max() < 2.0  # cm: the gait's path is kept
    extra = motion.accelerations(jolted).linear_acceleration_world - motion.accelerations(smooth).linear_acceleration_world
    gait = {motion.walk: motion._WALK, motion.run: motion._RUN, motion.hop: motion._HOP, motion.dance: motion._DANCE,
            motion.turn: motion._TURN, motion.jump: motion._JUMP}[source]
    assert 0.5 * gait.impact_g < np.abs(extra).max() / G < 3.0 * gait.impact_g
    rate = np.abs(np.diff(extra, axis=0)).max() / G * 120.0  # g/s: a ringing, not a one-frame step
    assert rate < 4 * np.pi * motion.IMPACT_HZ[1] * 2.0 * gait.impact_g
    spectrum = np.abs(np.fft.rfft(extra[:, 1] * np.hanning(len(extra)))) ** 2
    freqs = np.fft.rfftfreq(len(extra), 1 / 120.0)
    in_band = spectrum[(freqs >= 4.0) & (freqs <= 20.0)].sum() / spectrum.sum()
    assert in_band > 0.8
    turned = np.degrees(quaternion.angle_between(smooth.orient, jolted.orient))
    assert 0.01 < turned.max() < 3.0  # a small nod with each jolt
    strength = np.convolve(np.linalg.norm(extra, axis=1), np.ones(12) / 12, mode="same")
    assert 0.6 * gait.step_hz <= _dominant_hz(strength, 120.0) <= 1.4 * gait.step_hz  # one jolt per foot contact
    np.testing.assert_array_equal(source(6.0, 120.0, 3, impacts=True).translate, jolted.translate)  # seeded
