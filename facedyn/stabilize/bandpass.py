"""A zero-phase Butterworth band-pass in NumPy: what the inertia check filters the head's motion with.

scipy.signal.butter(2, band, "band", output="sos") followed by sosfiltfilt (odd padding,
steady-state initial conditions), to float rounding (tests/stabilize/test_bandpass.py
compares them), written out because importing scipy.signal costs 0.6-1 s, which every
stabilize command would pay for a filter of two second-order sections.
"""
from __future__ import annotations

import numpy as np


def butter_bandpass(low: float, high: float, fps: float) -> np.ndarray:
    """Second-order sections (2, 6) of the order-2 Butterworth band-pass from low to high Hz at fps.

    Bilinear transform of the analog prototype, pre-warped as scipy.signal.butter does;
    each section holds zeros at z = 1 and z = -1 and one conjugate pair of poles.
    """
    nyquist = 0.5 * fps
    if not 0.0 < low < high < nyquist:
        raise ValueError(f"band-pass edges must satisfy 0 < low < high < fps / 2, got {low}, {high} at {fps} fps")
    fs2 = 4.0  # 2 x the normalized sampling rate (Nyquist = 1)
    warped = fs2 * np.tan(0.5 * np.pi * np.array([low, high]) / nyquist)
    bandwidth, centre = warped[1] - warped[0], np.sqrt(warped[0] * warped[1])
    prototype = -np.exp(1j * np.pi * np.array([-1.0, 1.0]) / 4.0) * bandwidth / 2.0  # order-2 Butterworth poles, scaled
    root = np.sqrt(prototype**2 - centre**2)
    analog = np.concatenate([prototype + root, prototype - root])
    poles = (fs2 + analog) / (fs2 - analog)
    gain = bandwidth**2 * np.real(fs2**2 / np.prod(fs2 - analog))  # two analog zeros at 0
    upper = poles[np.imag(poles) > 0]
    if len(upper) != 2:  # a pole on the real axis: the band is too narrow or too wide to pair them
        raise ValueError(f"band-pass {low}-{high} Hz at {fps} fps has no two conjugate pole pairs")
    sos = np.zeros((2, 6))
    sos[:, :3] = [1.0, 0.0, -1.0]
    sos[0, :3] *= gain
    sos[:, 3] = 1.0
    sos[:, 4] = -2.0 * np.real(upper)
    sos[:, 5] = np.abs(upper) ** 2
    return sos


def filtfilt(sos: np.ndarray, x: np.ndarray) -> np.ndarray:
    """x (F, ...) filtered forward and backward along its first axis (zero phase), as scipy.signal.sosfiltfilt(sos, x, axis=0)."""
    x = np.asarray(x, dtype=np.float64)
    pad = 3 * (2 * len(sos) + 1)
    if len(x) <= pad:
        raise ValueError(f"filtering needs more than {pad} samples, got {len(x)}")
    extended = np.concatenate([2.0 * x[0] - x[pad:0:-1], x, 2.0 * x[-1] - x[-2:-pad - 2:-1]])
    steady = _steady_state(sos)
    y = _filter(sos, extended, steady, extended[0])
    y = _filter(sos, y[::-1], steady, y[-1])[::-1]
    return y[pad:-pad]


def _steady_state(sos: np.ndarray) -> np.ndarray:
    """(sections, 2): each section's state after a unit step has settled (scipy.signal.sosfilt_zi)."""
    states = np.empty((len(sos), 2))
    scale = 1.0
    for k, (b, a) in enumerate(zip(sos[:, :3], sos[:, 3:])):
        b = b / a[0]
        a = a / a[0]
        system = np.array([[1.0 + a[1], -1.0], [a[2], 1.0]])
        states[k] = scale * np.linalg.solve(system, b[1:] - a[1:] * b[0])
        scale *= b.sum() / a.sum()
    return states


def _filter(sos: np.ndarray, x: np.ndarray, steady: np.ndarray, first: np.ndarray) -> np.ndarray:
    """The cascade (direct form II transposed) along axis 0, each section started in its steady state for a
    constant input `first` (the cascade's, as scipy.signal.sosfilt with zi = sosfilt_zi(sos) * first)."""
    out = np.array(x, dtype=np.float64)
    for k, (b0, b1, b2, _, a1, a2) in enumerate(sos):
        z0, z1 = steady[k, 0] * first, steady[k, 1] * first
        y = np.empty_like(first)
        for t in range(len(out)):
            value = out[t]
            np.multiply(value, b0, out=y)
            y += z0
            z0 = b1 * value - a1 * y + z1
            z1 = b2 * value - a2 * y
            out[t] = y
    return out
