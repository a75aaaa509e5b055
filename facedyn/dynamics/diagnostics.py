"""Truth-free diagnostics of removed dynamics: what a studio can check on real captures.

A real capture has no true quasistatic shape, but removal must still behave in ways that
can be checked without one:
- a held expression's quasistatic shape is the same whatever the head does, so across
  takes of one held expression under different motions the shape left after removal
  should spread less than the captured shape did (`held_expression_spread`);
- a calibration session's takes each hold one expression, so everything on the face that
  moves in a take beyond its held shape and the sag that follows the head's turn is
  dynamics: the fraction of that motion a removal leaves (`motion_left_beyond_sag`) ranks
  removal models per actor (facedyn.dynamics.response uses it for its cross-validation);
- the skull's own rhythm (a platform's frequency, a gait's step rate) drives the
  dynamics, so after removal little of the capture's motion at that frequency should be
  left (`residual_at_frequency`; a platform take at a frequency training never saw is
  the held-out test);
- the synthesis network re-synthesizing the removed dynamics under the take's own motion
  should give back the capture (`resynthesis_residual`);
- the removed offsets should be where the skull's motion has energy and at the tissue's
  ringing, not below 1 Hz where expressions live (`offset_spectrum`).
Arrays only: points (F, N, 3) in skull space, cm; the skull as translate (F, 3) and
orient (F, 4, w x y z).
"""
from __future__ import annotations

import numpy as np

from facedyn.dynamics.skull_motion import skull_accelerations

PAD = 4  # zero-padding factor of the spectra (finer peak positions on short takes)
EXPRESSION_HZ = 1.0  # below this, motion is taken for expression change, not dynamics
BAND_HZ = 0.5  # half-width of the band around a frequency in residual_at_frequency


def power_spectrum(signal: np.ndarray, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """(frequencies Hz, power) of a (F, ...) signal summed over its other axes: Hann window,
    each channel's mean removed, zero-padded PAD times."""
    x = np.asarray(signal, dtype=np.float64).reshape(len(signal), -1)
    if len(x) < 4:
        raise ValueError(f"a spectrum needs at least 4 frames, got {len(x)}")
    x = (x - x.mean(axis=0)) * np.hanning(len(x))[:, None]
    n = PAD * len(x)
    power = (np.abs(np.fft.rfft(x, n, axis=0)) ** 2).sum(axis=1)
    return np.fft.rfftfreq(n, 1.0 / fps), power


def _skull_spectrum(translate: np.ndarray, orient: np.ndarray, landmarks: np.ndarray, fps: float) -> tuple[np.ndarray, np.ndarray]:
    """The power spectrum of the skull landmarks' accelerations in the skull frame (what drives
    the dynamics, and what network F reads)."""
    acc = skull_accelerations(translate, orient, landmarks, fps)[1:-1]
    return power_spectrum(acc, fps)


def peak_frequency(frequencies: np.ndarray, power: np.ndarray, above_hz: float = EXPRESSION_HZ) -> float:
    """The frequency of the largest power above `above_hz`."""
    keep = frequencies > above_hz
    if not np.any(keep):
        raise ValueError(f"no frequency above {above_hz} Hz in the spectrum")
    return float(frequencies[keep][np.argmax(power[keep])])


def held_expression_spread(takes: list[np.ndarray], vertices: np.ndarray, skip: int = 0) -> dict:
    """How far one held expression's shapes lie from their common mean, over takes and frames.

    takes: (F_k, N, 3) skull-space points of takes that hold one expression (under
    different motions); the first `skip` frames of each (the expression easing in) are left
    out. Returns RMS distances (cm) over `vertices`: ``per_frame_cm``, every frame against
    the mean shape of all takes; ``across_takes_cm``, each take's mean shape against it.
    """
    held = [np.asarray(p, dtype=np.float64)[skip:, vertices] for p in takes]
    if len(held) < 2 or any(len(p) == 0 for p in held):
        raise ValueError("the spread of a held expression needs at least two takes with frames after the ease-in")
    mean = np.concatenate(held).mean(axis=0)
    per_frame = np.concatenate([np.sum((p - mean) ** 2, axis=-1).ravel() for p in held])
    across = np.array([np.sum((p.mean(axis=0) - mean) ** 2, axis=-1).mean() for p in held])
    return {"per_frame_cm": float(np.sqrt(per_frame.mean())), "across_takes_cm": float(np.sqrt(across.mean()))}


def motion_left_beyond_sag(left: list[np.ndarray], motion: list[np.ndarray], rotations: list[np.ndarray]) -> float:
    """The fraction of held takes' motion that a removal leaves, beyond the held shapes and the sag.

    Per take k: motion[k] (rows, values) the captured skin (flattened coordinates, one row
    per frame), left[k] the same frames after removal, rotations[k] (rows, 9) the skull's
    rotation matrices. Each take is centred (its held shape); then a sag shared by the
    takes, linear in the rotation entries (gravity's direction seen from the skull), is
    fitted to each of the two and taken out, and the norms compare. Shared, because a
    platform rocks the head by a tenth of a degree at its own frequency: a take's own sag
    fit would take up its whole response.
    """
    if not (len(left) == len(motion) == len(rotations)) or not left:
        raise ValueError("motion_left_beyond_sag needs one left, motion and rotation array per take, at least one take")
    after, before = BeyondSag(), BeyondSag()
    for values_left, values_motion, rotation in zip(left, motion, rotations):
        after.add(values_left, rotation)
        before.add(values_motion, rotation)
    return after.norm() / max(before.norm(), 1e-30)


class BeyondSag:
    """The norm motion_left_beyond_sag compares, summed one take at a time.

    The shared sag is a least-squares fit on the centred rotation entries R; what is left
    beyond it has the squared norm |C|^2 - (R'C) . (R'R)^+ (R'C), so a take adds only its
    R'R, R'C and |C|^2 and need not stay in memory (a session of long takes, or several
    removals of it scored in one pass: SessionScore)."""

    def __init__(self):
        self.rr = np.zeros((9, 9))
        self.rc: np.ndarray | None = None
        self.squares = 0.0

    def add(self, values: np.ndarray, rotations: np.ndarray) -> None:
        """One take: values (rows, D), rotations (rows, 9)."""
        centred = np.asarray(values, dtype=np.float64)
        centred = centred - centred.mean(0)
        rotation = np.asarray(rotations, dtype=np.float64)
        rotation = rotation - rotation.mean(0)
        rc = rotation.T @ centred
        if self.rc is not None and rc.shape != self.rc.shape:
            raise ValueError(f"a take of {centred.shape[1]} values per row, the takes before {self.rc.shape[1]}")
        self.rr += rotation.T @ rotation
        self.rc = rc if self.rc is None else self.rc + rc
        self.squares += float(np.einsum("ij,ij->", centred, centred))

    def norm(self) -> float:
        if self.rc is None:
            raise ValueError("no take added")
        explained = float(np.einsum("ij,ij->", self.rc, np.linalg.pinv(self.rr, hermitian=True) @ self.rc))
        return float(np.sqrt(max(self.squares - explained, 0.0)))


class SessionScore:
    """How much of a calibration session's motion each of several removals leaves beyond
    held shapes and sag (`usdfacedyn evaluate --session`'s figure), in one pass over the takes.

    The tracker's spikes (pops, dropped frames) are replaced in each take's capture once
    (facedyn.dynamics.spikes): a pop is no dynamics any removal could take out, so what a
    removal leaves is the cleaned capture less its offsets. Takes are added one at a time
    and kept only as BeyondSag sums. vertices: the face's; skip: frames left out at each
    take's start (the expression easing in).
    """

    def __init__(self, vertices: np.ndarray, skip: int, removals: tuple[str, ...]):
        self.vertices, self.skip = np.asarray(vertices), int(skip)
        self.motion = BeyondSag()
        self.left = {name: BeyondSag() for name in removals}

    def add(self, captured: np.ndarray, orient: np.ndarray, offsets: dict) -> tuple[np.ndarray, np.ndarray]:
        """One take: its captured skull-space points (F, N, 3), skull orient (F, 4) and each removal's offsets (F, N, 3).
        Returns what the removals were scored against: the cleaned capture (rows, D) after the skipped
        frames, over the face's vertices, and the skull's rotations (rows, 9)."""
        from facedyn.dynamics.spikes import replace_spikes
        from facedyn.geometry import quaternion

        if set(offsets) != set(self.left):
            raise ValueError(f"offsets of {sorted(offsets)}, the score's removals are {sorted(self.left)}")
        rows = len(captured) - self.skip
        cleaned, _ = replace_spikes(np.asarray(captured)[:, self.vertices])
        cleaned = cleaned[self.skip:].reshape(rows, -1)
        rotations = quaternion.to_matrix(np.asarray(orient)[self.skip:]).reshape(rows, 9)
        self.motion.add(cleaned, rotations)
        for name, removed in offsets.items():
            self.left[name].add(cleaned - np.asarray(removed)[self.skip:, self.vertices].reshape(rows, -1), rotations)
        return cleaned, rotations

    def motion_left(self) -> dict:
        """{removal: the fraction of the session's motion beyond held shapes and sag it leaves}."""
        total = max(self.motion.norm(), 1e-30)
        return {name: sums.norm() / total for name, sums in self.left.items()}


def _band_amplitude(points: np.ndarray, fps: float, hz: float, vertices: np.ndarray) -> float:
    """RMS amplitude of `points` (F, N, 3) over `vertices` within BAND_HZ of `hz` (Parseval on the
    windowed spectrum: a relative measure, comparable between two signals of one take)."""
    frequencies, power = power_spectrum(np.asarray(points)[:, vertices], fps)
    band = np.abs(frequencies - hz) <= BAND_HZ
    return float(np.sqrt(power[band].sum()))


def residual_at_frequency(quasistatic: np.ndarray, captured: np.ndarray, fps: float, hz: float, vertices: np.ndarray) -> float:
    """The fraction of the capture's motion at `hz` (within BAND_HZ) that is left after removal."""
    before = _band_amplitude(captured, fps, hz, vertices)
    return _band_amplitude(quasistatic, fps, hz, vertices) / before if before > 0 else float("nan")


def resynthesis_residual(captured: np.ndarray, resynthesized: np.ndarray, quasistatic: np.ndarray, vertices: np.ndarray) -> float:
    """RMS(re-synthesized - captured) over `vertices` as a fraction of the removed dynamics' RMS."""
    v = np.asarray(vertices)
    removed = np.sqrt(np.mean(np.sum((captured[:, v] - quasistatic[:, v]) ** 2, axis=-1)))
    residual = np.sqrt(np.mean(np.sum((resynthesized[:, v] - captured[:, v]) ** 2, axis=-1)))
    return float(residual / removed) if removed > 0 else float("nan")


def offset_spectrum(offsets: np.ndarray, translate: np.ndarray, orient: np.ndarray, landmarks: np.ndarray, fps: float,
                    vertices: np.ndarray) -> dict:
    """The removed offsets' spectrum beside the skull's: peaks, and the offsets' power below
    EXPRESSION_HZ (expression motion F mistook for dynamics) as a fraction of all of it.
    Also returns both spectra (normalized to their maxima) for a plot."""
    frequencies, power = power_spectrum(np.asarray(offsets)[:, vertices], fps)
    skull_f, skull_p = _skull_spectrum(translate, orient, landmarks, fps)
    total = power[frequencies > 0].sum()
    return {
        "offsets_peak_hz": peak_frequency(frequencies, power),
        "skull_peak_hz": peak_frequency(skull_f, skull_p),
        "offsets_below_1hz_fraction": float(power[(frequencies > 0) & (frequencies < EXPRESSION_HZ)].sum() / total) if total > 0 else float("nan"),
        "spectra": {"hz": frequencies, "offsets": power / max(power.max(), 1e-30), "skull_hz": skull_f, "skull": skull_p / max(skull_p.max(), 1e-30)},
    }
