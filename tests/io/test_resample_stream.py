"""CubicResampler: a take resampled chunk by chunk equals the cubic spline through all of it."""
import numpy as np
import pytest
from scipy.interpolate import make_interp_spline

from facedyn.io.resample import COLUMN_BLOCK, SPLINE_CONTEXT, CubicResampler


def _whole(seconds, values, rate):
    """The spline through every sample (not-a-knot), on the grid from the first sample: the unchunked result."""
    count = int(np.floor((seconds[-1] - seconds[0]) * rate + 1e-6)) + 1
    grid = np.minimum(seconds[0] + np.arange(count, dtype=np.float64) / rate, seconds[-1])
    k = min(3, len(seconds) - 1)
    return make_interp_spline(seconds, values.astype(np.float64), k=k, axis=0)(grid).astype(np.float32)


def _chunked(resampler, values, chunk):
    return np.concatenate([resampler.resample(w, values[w.lo:w.hi]) for w in resampler.windows(chunk)])


@pytest.mark.slow  # resamples a take chunk by chunk, down to one frame a chunk, and whole (about 4 s)
@pytest.mark.parametrize("rate", [120.0, 50.0])
def test_chunks_equal_the_whole_spline_with_gaps_and_uneven_samples(rate):
    # 200 samples, 27 s: three times SPLINE_CONTEXT, so that even 500-frame chunks cut the context on both sides
    rng = np.random.default_rng(7)
    steps = rng.choice([1, 1, 1, 2, 3, 9, 40], size=199) / 60.0  # a 60 fps capture with dropped frames and long gaps
    seconds = 17.0 + np.concatenate([[0.0], np.cumsum(steps)])
    values = np.cumsum(rng.normal(0, 1, (200, COLUMN_BLOCK // 3 + 20, 3)), axis=0).astype(np.float32)  # more than a block of columns
    resampler = CubicResampler(seconds, rate)
    whole = _whole(seconds, values, rate)
    assert resampler.count == len(whole)
    for chunk in (1, 37, 500):
        windows = list(resampler.windows(chunk))
        assert [w.start for w in windows] == list(range(0, resampler.count, chunk)) and windows[-1].stop == resampler.count
        assert any(w.lo > 0 for w in windows) and any(w.hi < len(seconds) for w in windows)  # the context is a real cut
        chunked = _chunked(resampler, values, chunk)
        assert chunked.shape == whole.shape
        assert (np.abs(chunked - whole) <= np.spacing(np.abs(whole))).all()  # within float32 rounding of the whole spline


def test_each_window_holds_the_samples_around_its_frames_plus_the_context():
    seconds = np.arange(1000) / 30.0
    resampler = CubicResampler(seconds, 120.0)
    for w in resampler.windows(100):
        times = resampler.times(w.start, w.stop)
        assert seconds[w.lo + SPLINE_CONTEXT] <= times[0] or w.lo == 0
        assert times[-1] <= seconds[w.hi - 1 - SPLINE_CONTEXT] or w.hi == len(seconds)


def test_cubic_motion_is_reproduced_and_short_takes_fall_back_to_lower_degrees():
    seconds = np.array([0.0, 0.1, 0.15, 0.4, 0.5, 0.9])
    cubic = lambda t: (1 + 2 * t - 3 * t**2 + 4 * t**3)[:, None]  # noqa: E731
    resampler = CubicResampler(seconds, 100.0)
    np.testing.assert_allclose(_chunked(resampler, cubic(seconds), 7), cubic(np.arange(91) / 100.0), atol=1e-5)
    line = CubicResampler(np.array([1.0, 2.0]), 4.0)  # two samples: linear
    np.testing.assert_allclose(_chunked(line, np.array([[0.0], [4.0]]), 2), np.arange(5)[:, None], atol=1e-6)
    single = CubicResampler(np.array([3.0]), 24.0)
    assert single.count == 1 and _chunked(single, np.array([[5.0]]), 8).tolist() == [[5.0]]
    with pytest.raises(ValueError, match="increasing"):
        CubicResampler(np.array([1.0, 1.0, 2.0]), 24.0)
