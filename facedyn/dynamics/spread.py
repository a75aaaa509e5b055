"""The actor's own spread from the samples to the mesh, learned from how its session's skin moves.

Every model predicts offsets at a few hundred skin samples, and facedyn.dynamics.propagate
spreads them to every vertex as the smoothest (bi-Laplacian) field through them. A face does
not move as the smoothest field: a cheek follows the lip corner in the pattern its anatomy
gives it. On the test set's validation actors, sampling the *true* dynamics at F's 344 samples
and spreading them back already loses 11-28 % of their moving part, more than the held-out
platform's whole target; with the spread below, learned on the stabilized session, 4-10 %
(benchmarks/testset_spread.py, benchmarks/README-testset.md).

A calibration session shows how this actor's skin moves between the samples: every take's
motion about its mean (jiggle, sag, the held expression's drift and micro-motion alike). The
correction is a ridge regression from the samples' motion to what the bi-Laplacian spread
misses at every other vertex, fitted on that motion (each take less its mean over its
settled frames, the tracker's spikes replaced) and kept as its `RANK` leading directions:
``P' d = P d + (d A) B`` on those vertices, A (3S, r) and B (r, 3V). The rig's rigid region
is among them: the bi-Laplacian holds it at zero, but where the session shows it moving with
the samples (thin tissue over the bone still slides), the correction moves it the same way;
where it does not, the ridge leaves it near zero. It is linear, so it
serves removal, synthesis and a blend alike, and it is no model of dynamics: it only says
how the mesh between the samples moves with them. `usdfacedyn calibrate` fits it with the
actor's response and writes it into every model it makes for the actor (the arrays named
in `ARRAYS`); `DynamicsModel.propagator` applies it when a model carries it.
"""
from __future__ import annotations

import dataclasses
import functools
from typing import Iterable

import numpy as np

from facedyn.dynamics.skull import skull_space
from facedyn.dynamics.spikes import replace_spikes

RIDGE = 0.01  # per unit of the samples' mean variance in the session (the trace of their Gram / its size)
RANK = 96  # directions of the correction kept (of 3S)
VERTICES, INTO, OUT = "spread_vertices", "spread_into", "spread_out"
ARRAYS = (VERTICES, INTO, OUT)


@dataclasses.dataclass(frozen=True)
class Spread:
    """The correction added to the bi-Laplacian spread: on `vertices`, (d reshaped (F, 3S)) @ into @ out."""

    vertices: np.ndarray  # (V,) int32
    into: np.ndarray  # (3S, r) float32
    out: np.ndarray  # (r, 3V) float32
    point_count: int

    @functools.cached_property
    def _onto_mesh(self) -> np.ndarray:
        """(r, 3N) float32: `out` with zero columns for the other vertices, so that a frame's
        correction is one dense product added to its offsets (six times faster than adding it
        to the vertices by index on the built-in face)."""
        full = np.zeros((len(self.out), self.point_count, 3), np.float32)
        full[:, self.vertices] = self.out.reshape(len(self.out), -1, 3)
        return full.reshape(len(self.out), -1)

    def add_into(self, samples: np.ndarray, offsets: np.ndarray) -> None:
        """Add the correction of (F, S, 3) sample offsets to contiguous (F, N, 3) float32 mesh offsets, in place."""
        if not offsets.flags.c_contiguous:
            raise ValueError("the spread adds into contiguous (frames, points, 3) offsets")
        frames = len(samples)
        flat = np.ascontiguousarray(samples, dtype=np.float32).reshape(frames, -1)
        offsets.reshape(frames, -1)[:] += (flat @ self.into) @ self._onto_mesh

    def arrays(self) -> dict[str, np.ndarray]:
        """What a model file keeps of it (DynamicsModel.arrays)."""
        return {VERTICES: self.vertices, INTO: self.into, OUT: self.out}

    @classmethod
    def from_arrays(cls, arrays: dict, sample_count: int, point_count: int) -> "Spread | None":
        """The spread a model's arrays hold (None if they hold none), checked against its mesh."""
        present = [name for name in ARRAYS if name in arrays]
        if not present:
            return None
        if len(present) != len(ARRAYS):
            raise ValueError(f"the model holds {', '.join(present)} but not all of {', '.join(ARRAYS)}: its spread is incomplete")
        vertices = np.asarray(arrays[VERTICES])
        into, out = np.asarray(arrays[INTO], np.float32), np.asarray(arrays[OUT], np.float32)
        if not (vertices.ndim == 1 and np.issubdtype(vertices.dtype, np.integer) and vertices.size
                and vertices.min() >= 0 and vertices.max() < point_count and len(np.unique(vertices)) == len(vertices)):
            raise ValueError(f"the model's {VERTICES} are not distinct vertex indices of its {point_count}-point mesh")
        if into.ndim != 2 or into.shape[0] != 3 * sample_count or out.shape != (into.shape[1], 3 * len(vertices)):
            raise ValueError(f"the model's spread is {into.shape} and {out.shape}; its {sample_count} samples and "
                             f"{len(vertices)} vertices need (3S, r) and (r, 3V)")
        return cls(vertices.astype(np.int32), into, out, int(point_count))


def fit_spread(takes: Iterable, propagator, settle_frames: int, *, ridge: float = RIDGE, rank: int = RANK) -> tuple[Spread, dict]:
    """(the spread, its record) learned on session takes (TrainingSequence-like: points, translate,
    orient, space) for a propagator's samples; the record says how much of the motion between
    the samples the bi-Laplacian misses in the session, and how much with the spread (in sample).
    A spread the propagator already carries is not part of what is fitted against (a refit replaces it)."""
    propagator = dataclasses.replace(propagator, spread=None)
    samples = propagator.samples
    is_sample = np.zeros(propagator.matrix.shape[0], bool)
    is_sample[samples] = True
    free = np.flatnonzero(~is_sample).astype(np.int32)  # the rig's rigid region too: where the session moves it, it moves
    gram = moments = None
    missed = total = 0.0
    for take in takes:
        points, _ = replace_spikes(skull_space(take.points, take.translate, take.orient, take.space))
        motion = points[settle_frames:] - points[settle_frames:].mean(axis=0)
        x = motion[:, samples].reshape(len(motion), -1)
        y = (motion - propagator.apply(motion[:, samples]))[:, free].reshape(len(motion), -1)
        gram = x.T @ x if gram is None else gram + x.T @ x
        moments = x.T @ y if moments is None else moments + x.T @ y
        missed += float(np.sum(y ** 2))
        total += float(np.sum(motion[:, free] ** 2))
    if gram is None:
        raise ValueError("the spread needs at least one session take")
    scale = max(np.trace(gram) / len(gram), 1e-12)  # a session whose samples never move learns a spread that adds nothing
    regularized = gram + ridge * scale * np.eye(len(gram))
    weights = np.linalg.solve(regularized, moments)
    # the leading directions of the fitted values X W: the right singular vectors of C^T W, C C^T the Gram
    _, _, directions = np.linalg.svd(np.linalg.cholesky(regularized).T @ weights, full_matrices=False)
    out = directions[:rank]
    into = weights @ out.T
    kept = into @ out  # |X K - Y|^2 from the sums: |Y|^2 - 2 <K, X^T Y> + <G K, K>
    left = missed - 2.0 * float(np.sum(kept * moments)) + float(np.sum((gram @ kept) * kept))
    spread = Spread(free, into.astype(np.float32), out.astype(np.float32), len(is_sample))
    record = {"ridge": ridge, "rank": int(len(out)), "vertices": int(len(free)), "settle_frames": int(settle_frames),
              "session_missed_by_smoothest": round(float(np.sqrt(missed / max(total, 1e-30))), 4),
              "session_missed_with_spread": round(float(np.sqrt(left / max(total, 1e-30))), 4)}
    return spread, record


def fit_model_spread(model, takes: list, settle_s: float):
    """The model (an actor's, fitted on these session takes) carrying the spread learned on them."""
    settle = int(round(settle_s * model.fps))
    return with_spread(model, *fit_spread(takes, model.propagator(), settle))


def with_spread(model, spread: Spread, record: dict):
    """The model carrying the spread (its arrays and an info record; its propagator rebuilt when next asked for)."""
    arrays = {**{k: v for k, v in model.arrays.items() if k not in ARRAYS}, **spread.arrays()}
    return dataclasses.replace(model, arrays=arrays, info={**model.info, "spread": record}, _propagator=None)


def spread_of(model) -> tuple[Spread, dict] | None:
    """(the spread, its record) a model carries, or None."""
    spread = Spread.from_arrays(model.arrays, len(model.face.samples), model.face.point_count)
    return None if spread is None else (spread, model.info.get("spread", {}))
