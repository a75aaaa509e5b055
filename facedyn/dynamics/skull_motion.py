"""What the networks read of the skull's motion: which landmark vectors, over which frames.

Two kinds, both windows of per-frame landmark vectors in the skull frame of their frame:

- ``velocity`` (the paper, papers/000 eq. 2): bdot_l(k), the landmark's world velocity over
  the frame pair (k-1, k) rotated into the skull frame of k (facedyn.dynamics.features),
  over the frames t-10..t+10. F's default, computed by the feature kernel with X_i(t).
- ``acceleration`` (beyond the paper; H's default, F's with ``--skull-features acceleration``):
  ``a_l(k) = R_k^T (p_l(k+1) - 2 p_l(k) + p_l(k-1)) / dt^2`` with ``p_l(k) = R_k b_l + t_k``
  the landmark's world position, over the frames t-30..t+10.

Why facedyn departs from the paper. Tissue feels inertial loads: the skull's acceleration
and its rotation, never its velocity. A velocity in the skull frame also carries how fast
and in which direction the actor travels: walking forward at 1.3 m/s while looking around
turns that velocity inside the skull frame, which looks like a large load but is none. The
procedural walks of a training corpus travel at a few speeds, so a network learns their
speeds rather than the physics and fails on real mocap (CMU walking and hopping).
Accelerations are the same for any steady travel (Galilean invariant). The longer past
reaches over the tissue's memory: ten frames at 120 fps (83 ms) are less than one period
of soft tissue at 8 Hz, whose ring-down lasts about 0.2 s. The README's "What synthesis can
do" and "What removal can see" have the measured differences.

Ends: landmark positions are not extrapolated; a_l is zero at the first and last frame
(no neighbour on one side) and the windows read zeros outside the take, as for velocities.
The features are a few numbers per frame (5 landmarks), so NumPy computes them for every
backend.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facedyn.dynamics.features import check_fps, skull_velocities, span_windows
from facedyn.dynamics.skull import check_transforms
from facedyn.geometry import quaternion

KINDS = ("acceleration", "velocity")


@dataclass(frozen=True)
class SkullMotionInput:
    """What a network reads of the skull's motion: a kind of landmark vector over frames t-past..t+future."""

    kind: str = "acceleration"
    past: int = 30
    future: int = 10

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"skull motion features must be one of {KINDS}, got {self.kind!r}")
        for name in ("past", "future"):
            value = getattr(self, name)
            if int(value) != value or value < 0:
                raise ValueError(f"skull motion window {name} must be a non-negative whole number of frames, got {value}")

    @property
    def width(self) -> int:
        """Frames per window."""
        return self.past + self.future + 1

    def features(self, translate, orient, landmarks, fps: float, rows: tuple[int, int] | None = None) -> np.ndarray:
        """(F, L * width * 3) float32: landmark-major, then window entry, then x, y, z.

        rows (a, z): only the windows of frames a..z-1 (the same values), so a long take's
        windows are built a chunk at a time.
        """
        per_frame = (skull_accelerations if self.kind == "acceleration" else skull_velocities)(translate, orient, landmarks, fps)
        w = span_windows(per_frame.astype(np.float32), self.past, self.future, rows)
        return w.reshape(len(w), -1)

    def to_json(self) -> dict:
        return {"kind": self.kind, "past": self.past, "future": self.future}

    @classmethod
    def from_json(cls, value: dict) -> "SkullMotionInput":
        return cls(str(value["kind"]), int(value["past"]), int(value["future"]))


PAPER = SkullMotionInput("velocity", 10, 10)
"""The paper's input: B(t), the landmark velocities over t-10..t+10."""

NAMED = {"acceleration": SkullMotionInput(), "velocity": PAPER}
"""The inputs by the name `--skull-features` gives them."""


def skull_accelerations(translate, orient, landmarks, fps) -> np.ndarray:
    """(F, L, 3) float64 landmark accelerations in the skull frame of each frame; zero at both ends."""
    t, q = check_transforms(translate, orient)
    b = np.asarray(landmarks, dtype=np.float64)
    if b.ndim != 2 or b.shape[1] != 3 or len(b) == 0:
        raise ValueError(f"skull landmarks must be (L, 3) skull-space points, got {b.shape}")
    fps = check_fps(fps)
    rot = quaternion.to_matrix(q)
    world = np.einsum("fij,lj->fli", rot, b) + t[:, None, :]
    acc = np.zeros_like(world)
    acc[1:-1] = (world[2:] - 2.0 * world[1:-1] + world[:-2]) * fps * fps
    return np.einsum("fji,flj->fli", rot, acc)  # R_k^T a
