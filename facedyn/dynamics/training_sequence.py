"""One take's arrays as training and calibration read them: points, skull T(t), frame rate (no torch).

Kept apart from the trainer (facedyn.dynamics.training) so that what only reads takes, such
as fitting an actor's linear response, does not import torch.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facedyn.dynamics.face import FaceSetup
from facedyn.performance import Performance


@dataclass
class TrainingSequence:
    """One take's arrays prepared for training (not a USD take): the whole mesh, its skull T(t), frame rate."""

    name: str
    points: np.ndarray  # (F, N, 3) skull space (space="skull") or world space ("world")
    fps: float
    translate: np.ndarray | None = None  # (F, 3); None = identity
    orient: np.ndarray | None = None  # (F, 4) (w, x, y, z); None = identity
    space: str = "skull"
    dynamics: np.ndarray | None = None  # (F, N, 3) known secondary dynamics, skull frame (a simulated take's truth)
    face: FaceSetup | None = None  # the take's own face setup (a person-independent corpus of many faces); None: the model's

    @classmethod
    def coerce(cls, value) -> "TrainingSequence":
        """A TrainingSequence from a TrainingSequence or a dict with the same keys."""
        if isinstance(value, cls):
            return value
        if isinstance(value, dict):
            unknown = set(value) - set(cls.__dataclass_fields__)
            if unknown:
                raise ValueError(f"unknown take keys {sorted(unknown)}; a take has {sorted(cls.__dataclass_fields__)}")
            return cls(**value)
        raise ValueError(f"a take must be a TrainingSequence or a dict, got {type(value).__name__}")

    @classmethod
    def from_performance(cls, performance: Performance, name: str) -> "TrainingSequence":
        t, q = performance.skull()
        return cls(name, performance.points, performance.fps, t, q, "skull")
