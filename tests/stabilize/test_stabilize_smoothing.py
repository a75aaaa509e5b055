"""The solved skull's smoothness prior (facedyn.stabilize.smoothing): a penalized fit whose
cut-off GCV chooses per take; checked against the skull landmarks' true accelerations."""
import numpy as np
import pytest

from facedyn.dynamics.skull_motion import skull_accelerations
from facedyn.geometry import dualquat, quaternion
from facedyn.stabilize.smoothing import (ORDER, choose_cutoff, penalty_bands, smooth, smooth_skull_motion,
                                         smoothing_weight)

FPS = 120.0
LANDMARKS = np.array([[4.0, 3.0, 9.0], [-4.0, 3.0, 9.0], [0.0, -1.0, 11.0], [6.0, 1.0, 2.0], [-6.0, 1.0, 2.0]])
REST = np.random.default_rng(0).normal(size=(300, 3)) * 5.0


def skull_to_world(seconds: float, vibration_hz: float, amplitude_deg: float, amplitude_cm: float, fps: float = FPS):
    """A head turning slowly while it vibrates (a platform): translate (F, 3), orient (F, 4)."""
    t = np.arange(int(seconds * fps)) / fps
    vibration = np.sin(2 * np.pi * vibration_hz * t + 0.3)
    pitch = np.radians(amplitude_deg * vibration)
    yaw = np.radians(20.0 * np.sin(2 * np.pi * 0.4 * t))
    q = quaternion.multiply(np.stack([np.cos(yaw / 2), 0 * yaw, np.sin(yaw / 2), 0 * yaw], axis=1),
                            np.stack([np.cos(pitch / 2), np.sin(pitch / 2), 0 * pitch, 0 * pitch], axis=1))
    translate = np.stack([30.0 * t, 160.0 + amplitude_cm * vibration, 2.0 * np.sin(2 * np.pi * 0.7 * t)], axis=1)
    return translate, q


def with_pose_noise(translate, orient, cm: float, deg: float, seed: int):
    """Per-frame solved poses: the truth plus white noise, as world-to-skull dual quaternions."""
    rng = np.random.default_rng(seed)
    half_angles = np.radians(deg) / 2 * rng.normal(size=(len(orient), 3))
    wobble = quaternion.normalize(np.concatenate([np.ones((len(orient), 1)), half_angles], axis=1))
    noisy = dualquat.from_translate_orient(translate + rng.normal(scale=cm, size=translate.shape),
                                           quaternion.multiply(orient, wobble))
    return dualquat.conjugate(noisy)


def acceleration_error(world_to_skull, translate, orient) -> float:
    """RMS error of the landmarks' skull-frame accelerations, as a fraction of their RMS (ends excluded)."""
    solved_translate, solved_orient = dualquat.to_translate_orient(dualquat.conjugate(world_to_skull))
    solved = skull_accelerations(solved_translate, solved_orient, LANDMARKS, FPS)[1:-1]
    truth = skull_accelerations(translate, orient, LANDMARKS, FPS)[1:-1]
    return float(np.sqrt(np.mean((solved - truth) ** 2) / np.mean(truth**2)))


def test_penalty_bands_are_the_difference_operators_normal_matrix():
    for frames, order in [(11, 4), (9, 3), (6, 2), (5, 4)]:
        d = np.eye(frames)
        for _ in range(order):
            d = d[1:] - d[:-1]
        bands = penalty_bands(frames, order)
        full = np.zeros((frames, frames))
        for k in range(order + 1):
            for j in range(frames - k):
                full[j, j + k] = full[j + k, j] = bands[order - k, j + k]
        np.testing.assert_allclose(full, d.T @ d, atol=1e-12)


def test_a_sinusoid_at_the_cutoff_keeps_half_its_amplitude_and_one_far_below_it_all():
    frames = 2400
    t = np.arange(frames) / FPS
    middle = slice(600, 1800)  # far from the ends
    for hz, kept in [(20.0, 0.5), (5.0, 1.0)]:
        wave = np.sin(2 * np.pi * hz * t)[:, None]
        out = smooth(wave, np.ones(frames), smoothing_weight(20.0, FPS, ORDER), ORDER)
        gain = np.sqrt(np.mean(out[middle] ** 2) / np.mean(wave[middle] ** 2))
        assert gain == pytest.approx(kept, abs=0.01)


def test_a_9hz_vibrations_accelerations_are_recovered_from_noisy_per_frame_poses():
    translate, orient = skull_to_world(3.0, 9.0, 0.3, 0.05)
    noisy = with_pose_noise(translate, orient, cm=0.0001, deg=0.0003, seed=1)
    before = acceleration_error(noisy, translate, orient)
    smoothed, cutoff = smooth_skull_motion(noisy, FPS, REST)
    after = acceleration_error(smoothed, translate, orient)
    assert cutoff is not None and 12.0 <= cutoff <= 35.0  # passes 9 Hz, stops most of the noise
    assert after < 0.03 and after < before / 3, (before, after)


def test_fast_clean_motion_is_left_as_solved():
    translate, orient = skull_to_world(3.0, 14.0, 0.5, 0.1, fps=60.0)  # foot strikes at 60 fps, no noise
    exact = dualquat.conjugate(dualquat.from_translate_orient(translate, orient))
    smoothed, cutoff = smooth_skull_motion(exact, 60.0, REST)
    assert cutoff is None
    np.testing.assert_array_equal(smoothed, exact)


def test_dropped_frames_are_filled_from_their_neighbours():
    translate, orient = skull_to_world(3.0, 9.0, 0.3, 0.05)
    noisy = with_pose_noise(translate, orient, cm=0.0001, deg=0.0003, seed=2)
    tracked = np.ones(len(noisy), dtype=bool)
    tracked[[50, 51, 200]] = False
    held = noisy.copy()
    held[[50, 51]] = noisy[49]  # a tracker holding its last fit
    held[200] = noisy[199]
    filled, _ = smooth_skull_motion(held, FPS, REST, tracked)
    reference, _ = smooth_skull_motion(noisy, FPS, REST)
    assert acceleration_error(filled, translate, orient) < 1.5 * acceleration_error(reference, translate, orient)


def test_the_cutoff_is_not_chosen_on_takes_too_short_to_judge():
    paths = np.random.default_rng(3).normal(size=(2 * ORDER, 6))
    assert choose_cutoff(paths, np.ones(len(paths)), FPS) is None


def test_a_vibrations_ends_are_as_accurate_as_its_middle():
    """The motion is predicted past its ends before smoothing (smoothing.extend): seen from one side only, a smoother
    bends the accelerations of the first and last frames (a clean 9 Hz vibration at a 20 Hz cut-off: 9.5 % error
    there, 0.3 % in the middle); with the prediction the ends are as accurate as the middle."""
    translate, orient = skull_to_world(3.0, 9.0, 0.3, 0.05)
    clean = dualquat.conjugate(dualquat.from_translate_orient(translate, orient))
    truth = skull_accelerations(translate, orient, LANDMARKS, FPS)
    ends, middle = np.r_[1:10, len(clean) - 10:len(clean) - 1], np.arange(10, len(clean) - 10)

    def error(world_to_skull, frames):
        t, o = dualquat.to_translate_orient(dualquat.conjugate(world_to_skull))
        return float(np.sqrt(np.mean((skull_accelerations(t, o, LANDMARKS, FPS) - truth)[frames] ** 2) / np.mean(truth**2)))

    smoothed, _ = smooth_skull_motion(clean, FPS, REST, cutoff_hz=20.0)
    unextended, _ = smooth_skull_motion(clean, FPS, REST, cutoff_hz=20.0, extension=0)
    assert error(smoothed, ends) < 1.5 * error(smoothed, middle) < 0.01
    assert error(unextended, ends) > 10 * error(unextended, middle)  # what the prediction fixes
