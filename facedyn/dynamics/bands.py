"""Blending removals per frequency band: how much of each model's dynamics to take at each frequency.

Two removals of one take (the family's F and the actor's linear response) err differently at
different frequencies: F, trained on a corpus of many tissues, follows a platform's fast
ringing; the response, fitted on the actor's own session, follows the slow sway of a walk.
Their mean is one fixed choice; `BandWeights` weighs each model's offsets per band instead.

The bands are split by Gaussian low-passes at `edges_hz` (zero phase, no ripple), the top band
being what the highest low-pass leaves, so the bands of a signal add up to it exactly: equal
weights in every band are the mean, and a weight of 1 in every band is that model alone.
Everything is linear in the offsets, so the quasistatic shapes blend the same way.

`BandWeightsFit` chooses the weights without truth, on a calibration session (held
expressions: everything that moves beyond the held shapes and the head-following sag is
dynamics): the weights that leave the least of the session's motion, the figure
facedyn.dynamics.diagnostics.SessionScore computes, found in one pass over the takes because
that figure's square is a quadratic in the weights.
"""
from __future__ import annotations

import itertools
import json
from dataclasses import dataclass

import numpy as np

EDGES_HZ = (2.0, 4.0, 8.0)  # calibrate's bands, an octave each: a gait's steps, its harmonics and slow platforms, fast ringing
TRUNCATE = 3.0  # the low-pass kernels reach this many standard deviations
MAX_BANDS = 8  # what a model file may declare (checked on load)


def sigma_frames(hz: float, fps: float) -> float:
    """The Gaussian kernel's standard deviation (frames) whose low-pass passes half the power at `hz`."""
    return fps * np.sqrt(np.log(2.0)) / (2.0 * np.pi * hz)


def lowpass(signal: np.ndarray, hz: float, fps: float) -> np.ndarray:
    """`signal` (F, ...) low-passed along its frames at `hz` (float64); the ends are held (edge padding)."""
    from scipy.ndimage import correlate1d

    x = np.asarray(signal, dtype=np.float64)
    radius = reach_frames(hz, fps)
    if radius == 0 or len(x) == 0:
        return x.copy()
    t = np.arange(-radius, radius + 1)
    kernel = np.exp(-0.5 * (t / sigma_frames(hz, fps)) ** 2)
    return correlate1d(x, kernel / kernel.sum(), axis=0, mode="nearest")


def reach_frames(hz: float, fps: float) -> int:
    """Frames on each side the low-pass at `hz` reads."""
    return int(np.ceil(TRUNCATE * sigma_frames(hz, fps)))


def split(signal: np.ndarray, edges_hz: tuple[float, ...], fps: float) -> list[np.ndarray]:
    """The bands of `signal` (F, ...), lowest first: len(edges_hz) + 1 arrays that add up to it."""
    bands, below = [], np.zeros(np.shape(signal))
    for hz in edges_hz:
        low = lowpass(signal, hz, fps)
        bands.append(low - below)
        below = low
    bands.append(np.asarray(signal, dtype=np.float64) - below)
    return bands


@dataclass(frozen=True)
class BandWeights:
    """Per band (lowest first), each member model's weight; a band's weights add up to 1.

    edges_hz: the bands' edges, increasing (none: one band, the whole signal);
    weights: (bands, members)."""

    edges_hz: tuple[float, ...]
    weights: np.ndarray

    def __post_init__(self):
        w = np.asarray(self.weights, dtype=np.float64)
        edges = tuple(float(e) for e in self.edges_hz)
        if w.ndim != 2 or w.shape[0] != len(edges) + 1 or w.shape[1] < 1:
            raise ValueError(f"band weights need one row per band ({len(edges) + 1}) and a column per member, got shape {w.shape}")
        if len(edges) > MAX_BANDS - 1 or not all(np.isfinite(e) and e > 0 for e in edges) or list(edges) != sorted(set(edges)):
            raise ValueError(f"band edges must be at most {MAX_BANDS - 1} increasing positive frequencies, got {list(edges)}")
        if not np.all(np.isfinite(w)) or np.any(w < 0) or np.any(w > 1) or not np.allclose(w.sum(axis=1), 1.0, atol=1e-6):
            raise ValueError(f"each band's weights must lie in [0, 1] and add up to 1, got {w.tolist()}")
        object.__setattr__(self, "edges_hz", edges)
        object.__setattr__(self, "weights", w)

    @classmethod
    def mean(cls, members: int) -> "BandWeights":
        """Equal weights at every frequency: the mean of the members' removals."""
        return cls((), np.full((1, members), 1.0 / members))

    @property
    def members(self) -> int:
        return self.weights.shape[1]

    def is_mean(self) -> bool:
        return bool(np.allclose(self.weights, 1.0 / self.members))

    def reach(self, fps: float) -> int:
        """Frames of context on each side the blend reads beyond its members' own."""
        return max((reach_frames(hz, fps) for hz in self.edges_hz), default=0) if not self.is_mean() else 0

    def combine(self, removed: list, fps: float) -> tuple[np.ndarray, np.ndarray]:
        """(quasistatic points, offsets), float32: the members' removals of one take, [(quasistatic, offsets)], blended."""
        if len(removed) != self.members:
            raise ValueError(f"{len(removed)} removals for a blend of {self.members} members")
        if len(removed) == 1:
            return removed[0]
        return tuple(self._blend([r[i] for r in removed], fps).astype(np.float32) for i in (0, 1))

    def _blend(self, arrays: list, fps: float) -> np.ndarray:
        if self.is_mean():
            return np.mean(arrays, axis=0)
        per_band = [sum(w * np.asarray(a, dtype=np.float64) for w, a in zip(row, arrays)) for row in self.weights]
        return sum(split(mixed, self.edges_hz, fps)[b] for b, mixed in enumerate(per_band))

    def to_json(self) -> dict:
        return {"edges_hz": list(self.edges_hz), "weights": self.weights.round(6).tolist()}

    @classmethod
    def from_json(cls, record) -> "BandWeights":
        """From a model file's record (ValueError when it is not one)."""
        if not isinstance(record, dict) or set(record) != {"edges_hz", "weights"}:
            raise ValueError(f"band weights are {{'edges_hz': [...], 'weights': [[...], ...]}}, got {json.dumps(record)[:100]}")
        try:
            return cls(tuple(record["edges_hz"]), np.array(record["weights"], dtype=np.float64))
        except (TypeError, ValueError) as error:
            raise ValueError(str(error)) from None


class BandWeightsFit:
    """The per-band weights of two removals (a, b) that leave the least of a session's motion.

    What a blend leaves of a take is L(w) = C - b - sum_k w_k D_k, C the cleaned capture and
    D_k band k of (a - b), w_k band k's weight of a. The session figure's square (each take
    centred, the shared sag taken out: BeyondSag) is then c'Qc with c = (1, -w): takes add
    only the Gram sums of (C - b, D_1..D_K), their products with the centred rotations and
    the rotations' own (facedyn.dynamics.diagnostics.BeyondSag, per column pair).
    """

    def __init__(self, edges_hz: tuple[float, ...] = EDGES_HZ):
        self.edges_hz = tuple(edges_hz)
        columns = len(self.edges_hz) + 2
        self.gram = np.zeros((columns, columns))
        self.rr = np.zeros((9, 9))
        self.rc: np.ndarray | None = None

    def add(self, cleaned: np.ndarray, rotations: np.ndarray, a: np.ndarray, b: np.ndarray, fps: float, skip: int) -> None:
        """One take: cleaned (rows, D) its capture after `skip` frames; rotations (rows, 9); a, b the
        two removals' offsets over the whole take (F, D), F = skip + rows (the bands read every frame)."""
        rows = len(cleaned)
        b = np.asarray(b, dtype=np.float64)
        columns = np.empty((len(self.edges_hz) + 2, rows, np.shape(cleaned)[1]))
        columns[0] = cleaned - b[skip:]
        for k, band in enumerate(split(np.asarray(a, dtype=np.float64) - b, self.edges_hz, fps), start=1):
            columns[k] = band[skip:]
        columns -= columns.mean(axis=1, keepdims=True)  # each take centred (its held shape)
        rotation = np.asarray(rotations, dtype=np.float64)
        rotation = rotation - rotation.mean(0)
        flat = columns.reshape(len(columns), -1)
        self.gram += flat @ flat.T
        rc = np.matmul(rotation.T, columns)  # (columns, 9, D)
        self.rr += rotation.T @ rotation
        self.rc = rc if self.rc is None else self.rc + rc

    def _quadratic(self) -> np.ndarray:
        """Q: the squared figure beyond sag is c'Qc, c = (1, -w)."""
        if self.rc is None:
            raise ValueError("no take added")
        inverse = np.linalg.pinv(self.rr, hermitian=True)
        explained = np.einsum("iad,ab,jbd->ij", self.rc, inverse, self.rc)
        return self.gram - explained

    def left(self, w: np.ndarray) -> float:
        """The norm of the motion the blend with weights `w` (of a, per band) leaves beyond sag."""
        c = np.concatenate([[1.0], -np.asarray(w, dtype=np.float64)])
        return float(np.sqrt(max(c @ self._quadratic() @ c, 0.0)))

    def best(self) -> np.ndarray:
        """The weights of a in each band, each within [0, 1], that minimize what the blend leaves.

        A convex quadratic over a box of a few bands: every pattern of bands held at 0, held at 1
        or free is tried (3^bands small solves) and the feasible minimum kept."""
        q = self._quadratic()
        h, g = q[1:, 1:], -q[1:, 0]  # left^2 = q00 + 2 w'g + w'Hw
        bands = len(h)
        best_w, best_value = np.zeros(bands), np.inf
        for pattern in itertools.product((0.0, 1.0, None), repeat=bands):
            w = np.array([0.0 if p is None else p for p in pattern])
            free = np.array([p is None for p in pattern])
            if free.any():
                rhs = -(g[free] + h[np.ix_(free, ~free)] @ w[~free])
                solved, *_ = np.linalg.lstsq(h[np.ix_(free, free)], rhs, rcond=None)
                if np.any(solved < -1e-12) or np.any(solved > 1 + 1e-12):
                    continue
                w[free] = np.clip(solved, 0.0, 1.0)
            value = 2 * w @ g + w @ h @ w
            if value < best_value:
                best_w, best_value = w, value
        return best_w

    def weights(self) -> BandWeights:
        """The best weights as a blend of (a, b)."""
        w = self.best()
        return BandWeights(self.edges_hz, np.stack([w, 1.0 - w], axis=1))
