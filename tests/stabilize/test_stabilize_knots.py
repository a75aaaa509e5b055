"""The knot spacing chosen per take (facedyn.stabilize.knots): coarse where noise dominates, fine where motion does."""
import numpy as np

from facedyn.geometry import quaternion
from facedyn.stabilize.knots import EVERY_FRAME, choose_knot_spacing

FPS = 60.0


def maps(angle_deg: np.ndarray, shift_cm: np.ndarray):
    """World-to-skull maps of a head nodding about x by angle_deg and moving along y by shift_cm."""
    half = np.radians(angle_deg) / 2
    q = np.stack([np.cos(half), np.sin(half), np.zeros_like(half), np.zeros_like(half)], axis=1)
    return quaternion.to_matrix(q), np.stack([np.zeros_like(shift_cm), shift_cm, np.zeros_like(shift_cm)], axis=1)


def rest():
    return np.random.default_rng(0).normal(size=(200, 3)) * 5.0


def test_slow_noisy_motion_gets_a_smoothing_spline_and_fast_clean_motion_every_frame():
    t = np.arange(300) / FPS
    rng = np.random.default_rng(1)
    slow = maps(3.0 * np.sin(2 * np.pi * 0.5 * t) + rng.normal(scale=0.05, size=t.shape),
                0.5 * np.sin(2 * np.pi * 0.3 * t) + rng.normal(scale=0.01, size=t.shape))
    assert choose_knot_spacing(*slow, FPS, rest()) * FPS >= 3.0
    fast = maps(2.0 * np.sin(2 * np.pi * 14.0 * t), 0.3 * np.sin(2 * np.pi * 11.0 * t))  # foot strikes, a platform
    assert choose_knot_spacing(*fast, FPS, rest()) * FPS == EVERY_FRAME


def test_short_takes_are_knotted_every_frame():
    rot, trans = maps(np.zeros(3), np.zeros(3))
    assert choose_knot_spacing(rot, trans, FPS, rest()) == EVERY_FRAME / FPS
