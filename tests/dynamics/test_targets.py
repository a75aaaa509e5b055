"""Quasistatic targets (papers/000 eqs. 5-6): the moving average removes a jiggle."""
import numpy as np
import pytest

from facedyn.dynamics.skull import to_world
from facedyn.dynamics.targets import dynamic_offsets, moving_average, quasistatic_targets
from facedyn.geometry import quaternion


def held_expression_with_jiggle(frames=120, period=7.0, seed=0):
    rng = np.random.default_rng(seed)
    held = rng.normal(0, 5, (6, 3))  # the expression, skull space
    direction = rng.normal(0, 1, (6, 3))
    jiggle = 0.3 * np.sin(2 * np.pi * np.arange(frames) / period)[:, None, None] * direction
    time = np.arange(frames) / 120.0
    translate = np.stack([np.zeros(frames), 150 + 2 * np.sin(2 * np.pi * 1.5 * time), 0.5 * time], axis=1)
    orient = quaternion.from_rotvec(np.stack([0.2 * np.sin(2 * np.pi * time), 0.1 * time, np.zeros(frames)], axis=1))
    world = to_world(held[None] + jiggle, translate, orient)
    return world, translate, orient, held, jiggle


@pytest.mark.parametrize("period", [7.0, 10.5, 21.0])
def test_moving_average_removes_a_jiggle_whose_period_divides_the_window(period):
    world, t, q, held, jiggle = held_expression_with_jiggle(period=period)
    inner = slice(10, -10)  # away from the clamped ends
    y = quasistatic_targets(world, t, q, space="world")
    np.testing.assert_allclose(y[inner], to_world(np.broadcast_to(held, jiggle.shape), t, q)[inner], atol=1e-9)
    dx = dynamic_offsets(world, t, q, space="world")
    np.testing.assert_allclose(dx[inner], jiggle[inner], atol=1e-9)


def test_offsets_are_skull_frame_vectors_of_eq_6():
    world, t, q, _, _ = held_expression_with_jiggle(period=9.0)
    y = quasistatic_targets(world, t, q, space="world")
    rot = quaternion.to_matrix(q)
    expected = np.einsum("fji,fnj->fni", rot, world - y)  # T(t)^-1 (x - y): rotation only
    np.testing.assert_allclose(dynamic_offsets(world, t, q, space="world"), expected, atol=1e-9)


def test_a_long_period_jiggle_is_mostly_kept_as_expression():
    """Slow changes are expression, not dynamics: a 2 s wave passes the 21-frame mean."""
    world, t, q, held, jiggle = held_expression_with_jiggle(frames=480, period=240.0)
    dx = dynamic_offsets(world, t, q, space="world")[20:-20]
    assert np.sqrt(np.mean(dx**2)) < 0.05 * np.sqrt(np.mean(jiggle[20:-20] ** 2))


def test_clamped_ends_repeat_the_end_frames():
    v = np.arange(6, dtype=float)[:, None]
    out = moving_average(v, window=2)
    # frame 0 averages frames (0, 0, 0, 1, 2); frame 5 averages (3, 4, 5, 5, 5)
    np.testing.assert_allclose(out[:, 0], [3 / 5, 6 / 5, 2.0, 3.0, 19 / 5, 22 / 5])
    np.testing.assert_allclose(moving_average(v, window=0), v)


def test_a_window_longer_than_the_take_allocates_nothing_of_its_length():
    """A crafted model's 10,000-frame stretch window padded 20,000 frames onto a 70-frame take (1,700 times its size)."""
    import tracemalloc

    v = np.random.default_rng(0).random((7, 40, 3))
    for w in (7, 8, 50):  # each frame's window reaches past both ends: the same clamped mean as padding would give
        padded = np.pad(v, [(w, w), (0, 0), (0, 0)], mode="edge")
        expected = np.stack([padded[t:t + 2 * w + 1].mean(axis=0) for t in range(len(v))])
        np.testing.assert_allclose(moving_average(v, w), expected, rtol=1e-12)
    tracemalloc.start()
    moving_average(v, 10000)
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 10 * v.nbytes, peak


def test_bad_input_is_a_clear_error():
    with pytest.raises(ValueError, match="window"):
        moving_average(np.zeros((4, 3)), window=-1)
    with pytest.raises(ValueError, match="space"):
        dynamic_offsets(np.zeros((4, 2, 3)), space="camera")
    with pytest.raises(ValueError, match="orient"):
        dynamic_offsets(np.zeros((4, 2, 3)), np.zeros((4, 3)), np.zeros((3, 4)), space="world")
