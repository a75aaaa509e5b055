"""Performance.world_points: T(t) applied to the skull-space points, exactly as the per-frame formula gives."""
import numpy as np
import pytest

from facedyn.geometry import quaternion
from facedyn.performance import Performance, Topology


def take(frames, translate=None, orient=None):
    rng = np.random.default_rng(4)
    points = (rng.normal(size=(frames, 5, 3)) * 10).astype(np.float32)
    topology = Topology(np.array([3, 3], np.int32), np.array([0, 1, 2, 2, 3, 4], np.int32))
    return Performance(points, np.arange(frames, dtype=np.float64), 30.0, topology, translate, orient)


@pytest.mark.parametrize("frames", [1, 1500])  # more than one block of 1024 frames
def test_world_points_apply_the_skull_motion_in_float64(frames):
    rng = np.random.default_rng(5)
    orient = rng.normal(size=(frames, 4))
    orient /= np.linalg.norm(orient, axis=1, keepdims=True)
    translate = rng.normal(size=(frames, 3)) * 50
    perf = take(frames, translate, orient)
    expected = np.einsum("fij,fnj->fni", quaternion.to_matrix(orient), perf.points.astype(np.float64)) + translate[:, None]
    world = perf.world_points()
    assert world.dtype == np.float32
    np.testing.assert_allclose(world, expected, rtol=0, atol=1e-5)


def test_a_static_skull_gives_the_points_unchanged_in_a_copy():
    perf = take(3)
    world = perf.world_points()
    np.testing.assert_array_equal(world, perf.points)
    assert not np.shares_memory(world, perf.points)
