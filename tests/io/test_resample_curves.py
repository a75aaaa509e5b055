"""Expression curves onto regular grids: linear, clamped, on synthetic and real curves."""
import numpy as np
import pytest

from facedyn.io import livelink
from facedyn.io.resample import bracket, resample_curves, time_grid


def _curves(times, weights):
    return livelink.ExpressionCurves(
        times=np.asarray(times, dtype=np.float64), weights=np.asarray(weights, dtype=np.float32),
        names=[f"s{k}" for k in range(np.shape(weights)[1])], fps=30.0, unmapped=[],
    )


def test_time_grid():
    np.testing.assert_allclose(time_grid(0.0, 1.0, 4), [0, 0.25, 0.5, 0.75, 1.0])
    np.testing.assert_allclose(time_grid(0.5, 0.9, 10), [0.5, 0.6, 0.7, 0.8, 0.9])  # end kept despite rounding
    assert len(time_grid(2.0, 2.0, 30)) == 1
    with pytest.raises(ValueError, match="fps must be positive"):
        time_grid(0, 1, 0)


def test_bracket_clamps_and_handles_one_sample():
    lo, hi, w = bracket([0.0, 1.0, 3.0], [-1.0, 0.0, 0.5, 2.0, 3.0, 9.0])
    np.testing.assert_array_equal(lo, [0, 0, 0, 1, 1, 1])
    np.testing.assert_array_equal(hi, [1, 1, 1, 2, 2, 2])
    np.testing.assert_allclose(w, [0, 0, 0.5, 0.5, 1, 1])
    lo, hi, w = bracket([4.0], [3.0, 4.0, 5.0])
    np.testing.assert_array_equal(lo, [0, 0, 0])
    np.testing.assert_array_equal(hi, [0, 0, 0])


def test_linear_curves_are_reproduced_exactly():
    # Irregular samples (a dropped row) of two straight lines.
    times = np.array([0.0, 1 / 30, 2 / 30, 4 / 30, 5 / 30])
    curves = _curves(times, np.stack([2 * times, 1 - times], axis=1))
    out = resample_curves(curves, 120)
    assert out.fps == 120.0 and out.names == curves.names
    np.testing.assert_allclose(out.times, np.arange(21) / 120)
    np.testing.assert_allclose(out.weights[:, 0], 2 * out.times, atol=1e-6)
    np.testing.assert_allclose(out.weights[:, 1], 1 - out.times, atol=1e-6)
    assert out.weights.dtype == np.float32


def test_frame_count_clamps_beyond_the_span():
    curves = _curves([0.0, 0.1, 0.2], [[0.0], [1.0], [0.5]])
    out = resample_curves(curves, 20, frame_count=8)
    np.testing.assert_allclose(out.weights[:, 0], [0, 0.5, 1, 0.75, 0.5, 0.5, 0.5, 0.5])
    with pytest.raises(ValueError, match="frame_count and fps must be positive"):
        resample_curves(curves, 20, frame_count=0)


def test_real_curves_keep_their_samples(data_dir):
    shapes = ["jawOpen", "eyeBlink_L", "browInnerUp_L", "browInnerUp_R"]
    curves = livelink.read_livelink_csv(data_dir / "livelink-face" / "MySlate_3_Jason_Millers_iPhone.csv", shapes)
    out = resample_curves(curves, 120)
    assert len(out.times) == pytest.approx(curves.times[-1] * 120, abs=1)
    lo, hi, w = bracket(out.times, curves.times)  # original times land between new samples
    again = out.weights[lo] * (1 - w)[:, None] + out.weights[hi] * w[:, None]
    assert np.abs(again - curves.weights).max() < 0.05  # smooth speech curves survive a round trip
    assert out.weights.min() >= curves.weights.min() and out.weights.max() <= curves.weights.max()
