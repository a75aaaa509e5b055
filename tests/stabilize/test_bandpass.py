"""The inertia check's band-pass (facedyn.stabilize.bandpass) is SciPy's butter + sosfiltfilt, without importing scipy.signal."""
import numpy as np
import pytest
from scipy.signal import butter, sosfiltfilt

from facedyn.stabilize.bandpass import butter_bandpass, filtfilt


@pytest.mark.parametrize("fps, low, high", [(120.0, 0.7, 15.0), (60.0, 0.7, 15.0), (30.0, 0.7, 7.5), (240.0, 0.5, 40.0)])
def test_same_sections_and_output_as_scipy(fps, low, high):
    theirs = butter(2, [low / (0.5 * fps), high / (0.5 * fps)], btype="band", output="sos")
    ours = butter_bandpass(low, high, fps)
    # the same filter: equal frequency response (section order and gain split may differ)
    w = np.linspace(0.01, 0.99, 50) * np.pi
    def response(sos):
        z = np.exp(1j * w)[:, None]
        return np.prod((sos[:, 0] + sos[:, 1] / z + sos[:, 2] / z**2) / (sos[:, 3] + sos[:, 4] / z + sos[:, 5] / z**2), axis=1)
    np.testing.assert_allclose(response(ours), response(theirs), rtol=1e-9, atol=1e-12)
    x = np.random.default_rng(1).normal(size=(200, 7, 3)).cumsum(axis=0) + 5.0  # drifting, offset: padding and start states matter
    expected = sosfiltfilt(theirs, x, axis=0)
    np.testing.assert_allclose(filtfilt(ours, x), expected, rtol=0, atol=1e-10 * np.abs(expected).max())


def test_bad_band_and_short_signals_are_refused():
    with pytest.raises(ValueError, match="fps / 2"):
        butter_bandpass(0.7, 70.0, 120.0)
    with pytest.raises(ValueError, match="more than 15 samples"):
        filtfilt(butter_bandpass(0.7, 15.0, 120.0), np.zeros((15, 3)))
