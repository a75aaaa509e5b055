"""Tracker spikes in the skin that F reads: pops and dropped frames, replaced before features.

A tracker's pop (a feature mismatched for one frame) moves a few vertices by millimetres,
and a dropped frame (a tracker holding its last fit) puts the whole face, read through the
current skull, where the head was a frame ago. Both are one-frame spikes in skull space,
and F reads skin velocities: a 3 mm pop at 120 fps is a 36 cm/s velocity, five times a
running face's secondary motion, and it stays in F's window for 21 frames. On
`benchmarks/bench_cross_sim.py`'s running dialog (two volumetric actors, plain captures,
solved skull; F retrained on the same corpus with the same seed) the recommended F's
residual fell from 73% and 110% of the true dynamics to 38% and 63% with the spikes
replaced; the paper's F from 152% and 211% to 70% and 78%.

A sample is a spike in a frame where it is farther from the cubic through its two
neighbours on each side than SPIKE_FACTOR times the local typical distance (the median
over LOCAL_FRAMES on each side) and more than FLOOR_CM, and farther than in the two frames
on each side (a spike also pulls its neighbours' predictions). It is replaced by that
cubic; PASSES passes catch pops in neighbouring frames. A frame where most samples are
spikes was dropped: it is bridged whole first. Secondary dynamics stay under the threshold:
a held smile on an 11 Hz platform without tracker noise is untouched
(tests/dynamics/test_spikes.py), and in the demo-scale training corpus (0.1 mm of noise)
2 of its 3.5 million sample frames are replaced.

Only what F reads is cleaned: the layers keep the capture as it came.
"""
from __future__ import annotations

import numpy as np

from facedyn.stabilize.dropped import bridge_dropped

SPIKE_FACTOR = 6.0
FLOOR_CM = 0.02
LOCAL_FRAMES = 15
PASSES = 3
CANDIDATES_AT_ONCE = 1 << 16  # distances over the floor whose windows are compared at once (memory: 16 MB)
REACH = (PASSES + 1) * (LOCAL_FRAMES + 4)  # frames on each side a replacement can depend on (chunked callers add it as context)


def replace_spikes(trajectories: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(trajectories with one-frame spikes replaced, (F, S) bool of what was replaced).

    trajectories: (F, S, 3) points over time in skull space (float64 out). A frame where
    most samples are spikes is a dropped frame: it is bridged whole, with any dropped frame
    next to it, by the cubic through the two kept frames on each side
    (facedyn.stabilize.dropped); single samples are then replaced one by one. Takes
    shorter than five frames come back unchanged.
    """
    x = np.array(trajectories, dtype=np.float64)
    replaced = np.zeros(x.shape[:2], dtype=bool)
    if len(x) < 5:
        return x, replaced
    _, distance, over = _spike_distance(x)
    dropped = np.mean(over, axis=1) > 0.5
    dropped[[0, -1]] = False
    if dropped.any():
        x = bridge_dropped(x, ~dropped)
        replaced[dropped] = True
    for _ in range(PASSES):
        predicted, distance, over = _spike_distance(x)
        spikes = over & (distance >= _running_max(distance, 2))
        if not spikes.any():
            break
        x[spikes] = predicted[spikes]
        replaced |= spikes
    return x, replaced


def _running_max(values: np.ndarray, half: int) -> np.ndarray:
    """Each frame's maximum over frames t-half..t+half, the take's ends mirrored (SciPy's
    maximum_filter1d with mode 'reflect', without importing SciPy into every command)."""
    padded = np.pad(values, [(half, half)] + [(0, 0)] * (values.ndim - 1), mode="symmetric")
    frames = len(values)
    out = padded[:frames].copy()
    for shift in range(1, 2 * half + 1):
        np.maximum(out, padded[shift:shift + frames], out=out)
    return out


def _spike_distance(x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(every sample as its neighbours' cubic predicts it, (F, S) distance from that
    prediction, (F, S) whether that distance is over the spike threshold)."""
    predicted = _cubic_from_neighbours(x)
    distance = np.linalg.norm(x - predicted, axis=-1)
    return predicted, distance, _over_threshold(distance)


def _over_threshold(distance: np.ndarray) -> np.ndarray:
    """(F, S) whether each distance is over max(SPIKE_FACTOR times the median distance over
    LOCAL_FRAMES on each side, FLOOR_CM).

    The end frames predict themselves (distance 0): the typical distance near them comes
    from the frames inside, mirrored. Most distances are under the floor, so the median is
    only asked where they are not, and asked by counting: a distance d is over SPIKE_FACTOR
    times the median of a window of 2L+1 exactly when more than L of its SPIKE_FACTOR-fold
    values are below d (the same test as a median filter's, without filtering every sample).
    """
    inner = np.concatenate([distance[2:3], distance[1:-1], distance[-3:-2]])
    padded = np.pad(inner, ((LOCAL_FRAMES, LOCAL_FRAMES), (0, 0)), mode="reflect")  # a median filter's "mirror" ends
    over = distance > FLOOR_CM
    frames, samples = np.nonzero(over)
    offsets = np.arange(2 * LOCAL_FRAMES + 1)
    for start in range(0, len(frames), CANDIDATES_AT_ONCE):
        f, s = frames[start:start + CANDIDATES_AT_ONCE], samples[start:start + CANDIDATES_AT_ONCE]
        below = np.count_nonzero(SPIKE_FACTOR * padded[f[:, None] + offsets, s[:, None]] < distance[f, s][:, None], axis=1)
        over[f, s] = below > LOCAL_FRAMES
    return over


def _cubic_from_neighbours(x: np.ndarray) -> np.ndarray:
    """Each frame (of five or more) as the cubic through the two frames on each side predicts it; the second
    frame from an end from the cubic through the end frame and the three on its inner side.
    The end frames themselves predict themselves (never spikes: extrapolating to them would
    read a fast oscillation as one)."""
    p = x.copy()
    p[2:-2] = (-x[:-4] + 4.0 * x[1:-3] + 4.0 * x[3:-1] - x[4:]) / 6.0
    p[1] = 0.25 * x[0] + 1.5 * x[2] - x[3] + 0.25 * x[4]
    p[-2] = 0.25 * x[-1] + 1.5 * x[-3] - x[-4] + 0.25 * x[-5]
    return p
