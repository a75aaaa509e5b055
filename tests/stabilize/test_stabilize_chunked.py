"""A take solved in overlapping chunks is as accurate as solved whole, and its chunks share the whole take's spline."""
import numpy as np
import pytest

from facedyn.stabilize import Schedule, stabilize
from facedyn.stabilize.synthetic import synthetic_take


@pytest.fixture(scope="module")
def take():
    return synthetic_take(frames=720, vertices=400, fps=120.0, seed=5)


def vertex_errors(result, take):
    return np.linalg.norm(result.skull_points - take.skull, axis=-1)


@pytest.mark.slow  # solves a take whole and in chunks
def test_a_chunked_solve_is_as_accurate_as_the_whole_take_and_close_to_it(take):
    whole = stabilize(take.world, take.fps, rest=take.rest, chunk_frames=len(take.world))
    chunked = stabilize(take.world, take.fps, rest=take.rest, chunk_frames=192, chunk_overlap=32)
    whole_error, chunked_error = vertex_errors(whole, take), vertex_errors(chunked, take)
    # accuracy against the true skull-space skin equal within 0.001 cm (median, mean and 99th percentile)
    for statistic in (np.median, np.mean, lambda e: np.percentile(e, 99)):
        assert abs(statistic(chunked_error) - statistic(whole_error)) <= 1e-3
    difference = np.linalg.norm(chunked.skull_points - whole.skull_points, axis=-1).max(axis=1)  # per frame, largest
    assert np.median(difference) <= 2e-3 and difference.max() <= 1e-2


@pytest.mark.parametrize("first, frames", [(0, 720), (150, 200), (517, 203), (3, 2)])
def test_a_chunks_spline_knots_are_the_whole_takes_inside_it(first, frames):
    schedule = Schedule()
    whole = schedule.coarse_knots(0, 720, 120.0)
    knots = schedule.coarse_knots(first, frames, 120.0)
    last = first + max(frames - 1, 1)
    assert np.all(knots[:4] == first) and np.all(knots[-4:] == last)  # clamped at the chunk's ends
    inside = whole[(whole > first) & (whole < last)]
    np.testing.assert_array_equal(knots[4:-4], inside)  # and the whole take's knots between them
    assert np.all(np.diff(knots) >= 0)
