"""The solved skull's smoothness prior: a penalized fit of its motion, cut-off chosen per take.

Mode pursuit's spline follows the tracked rigid mode closely, and with it the tracking noise
that each frame's fit carries. Twice differentiated (the skull landmarks' accelerations,
the networks' input) that noise dominates: per frame, white noise of 0.002 cm in position
is several % of a 9 Hz vibration's acceleration. A regression spline with coarser knots
smooths it, but it cannot both follow a 9 Hz vibration and reject noise at 15-30 Hz, its
piecewise-linear accelerations leave an error at the knot rate, and its clamped ends
bend the accelerations of the first and last frames.

So the motion is smoothed last, by penalized least squares (a Whittaker smoother, the
discrete smoothing spline with a knot per frame): minimize
``sum_f w_f |z_f - y_f|^2 + lambda sum_f |Delta^m z_f|^2`` over the frames' dual
quaternions z (skull to world, about the rigid region's centre, so that a turn does not
swing a far origin), then normalize. Its transfer function
``1 / (1 + lambda (2 sin(pi f / fps))^(2m))`` is a low-pass with no knot-rate artefacts,
of gain 1/2 at the cut-off ``f_c``; of order m = 4 (a penalty on the 4th difference) it
is flat far below f_c and steep above it, and it is locally cubic at the take's ends,
where a lower order forces the accelerations to a constant (m = 3) or zero (m = 2).
Dropped frames get weight 0 (the smoother fills them from both sides). On the plain
captures of benchmarks/bench_stabilize_plain.py the landmarks' acceleration error went
from 4.3 % to 1.6 % on a 9 Hz platform at 120 fps (cut-off 23 Hz) and from 2.0 % to
0.6 % on a dialog under a CMU walk (20 Hz); a run at 60 fps is left as solved (0.7 %).

At the take's ends the smoother sees data on one side only, and the accelerations of the
first and last ten frames carried half the error that was left (a 9 Hz platform: 1.6 %
over the take, 1.2 % without them). So the motion is first extended past each end by a
linear prediction (an autoregressive model of AR_ORDER fitted to each component of the
take, EXTENSION frames), smoothed, and cut back: the platform's error became 1.2 %, a
dialog under a CMU walk's 0.67 % became 0.55 %, and no tuned case got worse by more than
0.02 points (benchmarks/bench_stabilize_plain.py's built-in face takes).

The cut-off is chosen per take by generalized cross-validation (GCV) of the solved motion
itself, at probe points around the rigid region: the residual of each candidate cut-off
weighed against the smoother's degrees of freedom (its hat matrix's trace, from the
penalty's cosine-transform eigenvalues), with no noise level to know; choose_cutoff says
which candidate it takes.
"""
from __future__ import annotations

from math import comb

import numpy as np
from scipy.linalg import solveh_banded

from facedyn.geometry import dualquat

ORDER = 4
CUTOFFS_HZ = (6.0, 8.0, 10.0, 12.0, 14.0, 16.0, 18.0, 20.0, 23.0, 26.0, 30.0, 35.0, 40.0, 45.0)  # GCV's candidates
TOLERANCE = 0.1  # how far above GCV's minimum score the chosen cut-off may score
AR_ORDER = 8  # the linear prediction that extends the motion past its ends
EXTENSION = 20  # frames predicted past each end


def penalty_bands(frames: int, order: int) -> np.ndarray:
    """D^T D for the order-th difference D over frames, in solveh_banded's upper form."""
    stencil = np.array([(-1.0) ** (order - i) * comb(order, i) for i in range(order + 1)])
    bands = np.zeros((order + 1, frames))
    rows = frames - order  # difference row r covers frames r .. r + order
    for i in range(order + 1):  # row r adds stencil[i] * stencil[i + k] at (r + i, r + i + k)
        for k in range(order + 1 - i):
            bands[order - k, i + k : i + k + rows] += stencil[i] * stencil[i + k]
    return bands


def smoothing_weight(cutoff_hz: float, fps: float, order: int) -> float:
    """lambda with a half-power cut-off at cutoff_hz."""
    return float((2.0 * np.sin(np.pi * min(cutoff_hz / fps, 0.5))) ** (-2 * order))


def smooth(values: np.ndarray, weights: np.ndarray, lam: float, order: int, bands: np.ndarray | None = None) -> np.ndarray:
    """(F, K) values smoothed: (W + lam D^T D) z = W y, banded."""
    frames = len(values)
    if frames <= order:
        return np.array(values, dtype=np.float64)
    a = lam * (penalty_bands(frames, order) if bands is None else bands)  # a new array: bands is kept
    a[-1] += weights
    return solveh_banded(a, weights[:, None] * values, check_finite=False)


def _degrees_of_freedom(frames: int, lam: float, order: int) -> float:
    """Trace of the smoother's hat matrix (all weights 1), from the penalty's eigenvalues."""
    eigen = (2.0 * np.sin(np.pi * np.arange(frames) / (2.0 * frames))) ** (2 * order)
    return float(np.sum(1.0 / (1.0 + lam * eigen)))


def choose_cutoff(paths: np.ndarray, weights: np.ndarray, fps: float, order: int = ORDER,
                  candidates: tuple[float, ...] = CUTOFFS_HZ) -> float | None:
    """The cut-off (Hz) for (F, K) paths by GCV, or None: no smoothing.

    GCV's score is the positions' error; accelerations want more smoothing than that, so
    the cut-off is the lowest whose score is within TOLERANCE of GCV's minimum (its score
    is flat about the minimum: at 60 fps a dialog scores within 2.5% from 23 to 30 Hz,
    where 20 Hz halves the accelerations' error of 30 Hz). GCV cannot judge no smoothing
    (it interpolates), so when the score is lowest at the highest candidate at most the
    Nyquist rate, the motion is faster than any smoothing keeps (a run's foot strikes at
    60 fps) and it is left as solved.
    """
    frames = len(paths)
    judged = [c for c in candidates if c <= fps / 2.0]
    if frames <= 2 * order or len(judged) < 2:
        return None
    bands = penalty_bands(frames, order)
    used = max(float(weights.sum()), 1.0)
    scores = []
    for cutoff in judged:
        lam = smoothing_weight(cutoff, fps, order)
        fitted = smooth(paths, weights, lam, order, bands)
        free = 1.0 - _degrees_of_freedom(frames, lam, order) / used
        residual = np.sum(weights[:, None] * (fitted - paths) ** 2) / used
        scores.append(residual / (free * free) if free > 0 else np.inf)
    scores = np.array(scores)
    if int(np.argmin(scores)) == len(judged) - 1:
        return None
    return float(judged[int(np.argmax(scores <= (1.0 + TOLERANCE) * scores.min()))])


def smooth_skull_motion(world_to_skull: np.ndarray, fps: float, rest: np.ndarray, tracked: np.ndarray | None = None,
                        order: int = ORDER, cutoff_hz: float | None = None,
                        extension: int = EXTENSION) -> tuple[np.ndarray, float | None]:
    """(F, 8) world-to-skull dual quaternions smoothed, and the cut-off used (Hz).

    rest: (Na, 3) the rigid region in skull space (its centre is where the motion is
    smoothed about, its RMS radius places GCV's probe points); tracked: (F,) False on
    dropped frames; cutoff_hz: None chooses it by GCV (choose_cutoff); extension: frames
    predicted past each end (extend; 0: none). The cut-off comes back as None where GCV
    chose not to smooth (the maps come back as they were).
    """
    frames = len(world_to_skull)
    weights = np.ones(frames) if tracked is None else np.asarray(tracked, dtype=np.float64)
    rest = np.asarray(rest, dtype=np.float64)
    center = rest.mean(axis=0)
    skull_to_world = dualquat.normalize(dualquat.conjugate(world_to_skull))
    rot, trans = dualquat.to_rotation_translation(skull_to_world)
    shift = np.einsum("fij,j->fi", rot, center) + trans - center  # where the centre moves
    about_center = dualquat.make_continuous(dualquat.from_translate_orient(shift, skull_to_world[:, :4]))
    if cutoff_hz is None:
        radius = float(np.sqrt(np.mean(np.sum((rest - center) ** 2, axis=1))))
        probes = radius * np.concatenate([np.eye(3), -np.eye(3)])
        r, t = dualquat.to_rotation_translation(about_center)
        paths = (np.einsum("fij,pj->fpi", r, probes) + t[:, None]).reshape(frames, -1)
        cutoff_hz = choose_cutoff(paths, weights, fps, order)
        if cutoff_hz is None:
            return world_to_skull, None
    lam = smoothing_weight(cutoff_hz, fps, order)
    extended, weights = extend(about_center, weights, lam, order, frames=extension)
    smoothed = smooth(extended, weights, lam, order)
    smoothed = dualquat.normalize(smoothed[(len(extended) - frames) // 2:][:frames])
    r, shift = dualquat.to_rotation_translation(smoothed)
    translate = shift + center - np.einsum("fij,j->fi", r, center)
    skull_to_world = dualquat.from_translate_orient(translate, smoothed[:, :4])
    return dualquat.conjugate(skull_to_world), cutoff_hz


def extend(values: np.ndarray, weights: np.ndarray, lam: float, order: int = ORDER, ar_order: int = AR_ORDER,
           frames: int = EXTENSION) -> tuple[np.ndarray, np.ndarray]:
    """(F, K) values with `frames` more predicted before and after (AR(ar_order) per component, least squares on the
    take, run backwards for the start), and their weights (1 on the predictions); as they are on takes too short to
    fit a prediction (4 x ar_order frames). The prediction learns from the frames of positive weight, the others
    (dropped frames, whatever they hold) taken from the take smoothed as it is (lam, order)."""
    if len(values) < 4 * ar_order or frames == 0:
        return values, weights
    if np.any(weights <= 0):
        values = np.where((weights > 0)[:, None], values, smooth(values, weights, lam, order))
    before = _predicted(values[::-1], ar_order, frames)[::-1]
    after = _predicted(values, ar_order, frames)
    return np.concatenate([before, values, after]), np.concatenate([np.ones(frames), weights, np.ones(frames)])


def _predicted(values: np.ndarray, order: int, frames: int) -> np.ndarray:
    """(frames, K): each column continued past its end by its own least-squares AR(order) model."""
    mean = values.mean(axis=0)
    centred = values - mean
    count = len(values) - order
    lags = np.stack([centred[order - j - 1:order - j - 1 + count] for j in range(order)], axis=1)  # (count, order, K): lag j + 1
    coefficients = np.stack([np.linalg.lstsq(lags[:, :, k], centred[order:, k], rcond=None)[0]
                             for k in range(values.shape[1])], axis=1)  # (order, K)
    history = centred[:-order - 1:-1].copy()  # (order, K), the latest frame first
    out = np.empty((frames, values.shape[1]))
    for i in range(frames):
        out[i] = np.sum(coefficients * history, axis=0)
        history = np.concatenate([out[i:i + 1], history[:-1]])
    return out + mean
