"""The expression's own inertia, read off an actor's linear response, for removal.

Tissue that hangs on a moving rest shape feels that shape's acceleration as a load, -y''(t),
the same load as a translation acceleration of the skull (facedyn.sim.volumetric puts both
on every node of its layer; facedyn.sim.tissue with `expression_inertia`). A linear
response (facedyn.dynamics.response) reads the skull alone, so it misses the jiggle of a
fast lip or jaw motion (on the benchmark's walking dialog about a third of the dynamics),
but its weights summed over the landmarks are each sample's answer to a uniform
acceleration impulse (`translation_kernel`), and that kernel applied to a sample's own
acceleration answers the load.

Removal does not know y: it takes the capture less the skull-driven dynamics the response
predicts, low-passed with a zero-phase Butterworth below the tissue's band (`LOWPASS_HZ`);
above it that difference is mostly tracker noise and the acceleration of the dynamics
themselves, which are no load. What this answers is therefore not only the expression's
inertia: below the band the difference also holds what the response under-predicted, and
answering it as a load adds a share of it back. Measured, not derived:

- facedyn.sim.tissue with expression_inertia 1, still head, procedural speech
  (tests/dynamics/test_response.py): the term removes 13 % of the jiggle (a uniform
  kernel over-predicts loads that vary over the face, which the membrane resists: on the
  true y unfiltered it leaves 116 %); walking with speech 37 % -> 33 %; but an 8 Hz
  platform under a held expression 48 % -> 52 %.
- facedyn.sim.volumetric, prototype actors 1801 / 1802 / 1804, tracker-noisy captures, true
  skull: walking dialog 53 / 35 / 76 % -> 47 / 32 / 66 %, and the hop, the run and the
  8 Hz platform improved on all three (1804's platform 33 % -> 29 %); cut-offs of 3, 5, 8
  and 12 Hz were tried there, 5 was best or near it on each. The held-out figures are the
  benchmark's (README).

Synthesis answers the same load on the quasistatic skin it is given, spikes replaced and
low-passed alike (a quasistatic layer is a capture less its removed dynamics: it keeps the
tracker's noise and pops). On the prototype actors 1801 / 1802 / 1804 (response fitted on
the tracker-noisy session, true skull, ridges 0.03 / 0.03 / 1), the hop's synthesis from its
own true quasistatic skin plus tracker noise went 31.3 / 46.1 / 73.6 % -> 31.1 / 40.8 /
73.7 %, and the walking dialog's quasistatic skin under the hop's skull (simulated again:
a retargeting's truth) 50.6 / 44.0 / 53.1 % -> 48.9 / 42.6 / 53.0 %; 8 Hz took more on 1801 and
1802 but fed the response's own removal leftovers back on 1804 (its hop 73.6 % -> 83 % from
the quasistatic its removal left, against 67 % at 5 Hz), so synthesis keeps removal's cut-off.

A response file fitted before the term carries no `expression_inertia_hz` and removes and
synthesizes with the skull alone, as it did.
"""
from __future__ import annotations

import numpy as np

LOWPASS_HZ = 5.0  # below the family's 5-9 Hz tissue band's ring (about 15 % above soft_hz)
_ORDER = 2  # Butterworth order, run forwards and backwards


def filter_reach(fps: float, lowpass_hz: float = LOWPASS_HZ) -> int:
    """Frames over which the low-pass's answer to an impulse decays below 1e-7 (a second-order
    Butterworth's poles decay at sqrt(1/2) 2 pi lowpass_hz per second): the context a chunk of
    a take needs so that the filter gives what it gives on the whole take."""
    return int(np.ceil(np.log(1e7) * fps / (np.sqrt(0.5) * 2.0 * np.pi * lowpass_hz)))


def translation_kernel(weights: np.ndarray, landmarks: int, past: int, future: int) -> np.ndarray:
    """(past + future + 1, S, 3, 3) float64: K[lag + future][s, :, j] is sample s's offset `lag`
    frames after a unit skull acceleration along j (cm per cm/s^2), lags -future..past.

    weights: (features, 3S) response on the raw acceleration features, laid out landmark, then
    window entry (frames t-past..t+future), then axis (SkullMotionInput.features). A uniform
    acceleration at frame k is the same on every landmark, so the answer at t sums the
    landmarks' weights on the window entry that reads frame k = t - lag.
    """
    width = past + future + 1
    w = np.asarray(weights, dtype=np.float64)
    if w.shape[0] != landmarks * width * 3 or w.shape[1] % 3:
        raise ValueError(f"response weights {w.shape} do not fit {landmarks} landmarks over {width} frames")
    per_entry = w.reshape(landmarks, width, 3, -1, 3).sum(axis=0)  # (entry, j, S, i)
    by_lag = per_entry[::-1]  # entry past - lag -> index lag + future
    return np.ascontiguousarray(by_lag.transpose(0, 2, 3, 1))  # (lag, S, i, j)


def expression_inertia(kernel: np.ndarray, skin: np.ndarray, fps: float, future: int, lowpass_hz: float = LOWPASS_HZ) -> np.ndarray:
    """(F, S, 3) float64: the offsets the skin's own acceleration below `lowpass_hz` loads.

    kernel: `translation_kernel`; skin: (F, S, 3) skull-space sample positions of the
    expression (for removal: the capture less the skull-driven dynamics). The acceleration
    is zero at both ends and read as zero outside the take, like the skull's features.
    """
    y = np.asarray(skin, dtype=np.float64)
    frames = len(y)
    if frames < 3:
        return np.zeros_like(y)
    from scipy.signal import butter, filtfilt  # here: scipy.signal takes ~1 s to import, and remove/synthesize with F or H never filter

    b, a = butter(_ORDER, lowpass_hz / (0.5 * fps))
    smooth = filtfilt(b, a, y, axis=0, padlen=min(3 * max(len(a), len(b)), frames - 1))
    acc = np.zeros_like(y)
    acc[1:-1] = (smooth[2:] - 2.0 * smooth[1:-1] + smooth[:-2]) * fps * fps
    return convolve(kernel, acc, future)


def convolve(kernel: np.ndarray, load: np.ndarray, future: int) -> np.ndarray:
    """(F, S, 3) float64: each sample's answer through `kernel` (`translation_kernel`) to its
    own load series (F, S, 3): out[t] = sum over lags of K[lag + future] load[t - lag], lags
    -future..past, read as zero outside the take. By FFT: a fit convolves every session take
    several times, which lag by lag took 17x longer."""
    from scipy import fft as sfft  # here: F's removal reads this module's reach, and SciPy's import is a command's 0.1 s

    load = np.asarray(load, dtype=np.float64)
    frames, taps = len(load), len(kernel)
    if frames == 0:
        return np.zeros_like(load)
    n = sfft.next_fast_len(frames + taps - 1, real=True)
    spectrum = np.einsum("fsij,fsj->fsi", sfft.rfft(kernel, n, axis=0), sfft.rfft(load, n, axis=0))
    return sfft.irfft(spectrum, n, axis=0)[future:future + frames]
