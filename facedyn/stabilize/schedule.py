"""The continuation schedule of mode pursuit: penalty widths, iterations, spline levels.

Widths follow papers/001: positions 0.8 .. 0.05 cm, velocities 0.2 .. 0.0125 cm/frame.
A per-frame width means nothing without a frame rate, so velocity widths are read as
cm/frame at ``reference_fps`` (120 fps, the middle of the 96-128 fps capture rates the
project targets) and used as cm/s = width x reference_fps: a take at another rate is
held to the same physical speeds. Knot spacing is in seconds for the same reason.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

REFERENCE_FPS = 120.0


@dataclass(frozen=True)
class Stage:
    index: int
    width_pos: float  # cm
    width_vel: float  # cm/s
    refine: bool  # midpoint-refine the control polygon before this stage


@dataclass(frozen=True)
class Schedule:
    """Widths per stage, a fixed L-BFGS iteration count per stage, and the spline levels.

    The finest spline has knots every ``knot_spacing`` seconds; it is reached after
    ``refinements`` midpoint refinements, done before stages 1..refinements (each halves
    the spacing), so the first stage runs on a 2^refinements times coarser spline. The
    spacing is the smoothness prior: 1/80 s still smooths over single-frame tracking
    noise at 96-128 fps, and follows both 6-11 Hz platform vibration and fast head turns
    (real CMU walking turns the head at up to ~300 deg/s; 1/40 s left up to 1.4 deg of
    error there, 1/80 s about 0.04 deg: benchmarks/bench_stabilize_accuracy.py).
    """

    widths_pos: tuple[float, ...] = (0.8, 0.4, 0.2, 0.1, 0.05)
    widths_vel: tuple[float, ...] = (0.2, 0.1, 0.05, 0.025, 0.0125)
    reference_fps: float = REFERENCE_FPS
    iterations: int = 12
    knot_spacing: float | None = 1.0 / 80.0  # None: a knot per frame, then smoothed per take (facedyn.stabilize.smoothing)
    refinements: int = 2

    def __post_init__(self) -> None:
        if len(self.widths_pos) != len(self.widths_vel) or not self.widths_pos:
            raise ValueError(
                f"need one velocity width per position width, got {len(self.widths_pos)} and {len(self.widths_vel)}"
            )
        if min(self.widths_pos) <= 0 or min(self.widths_vel) <= 0:
            raise ValueError("penalty widths must be positive")
        if not self.reference_fps > 0:
            raise ValueError(f"reference_fps must be positive, got {self.reference_fps}")
        if self.iterations < 1:
            raise ValueError(f"iterations per stage must be >= 1, got {self.iterations}")
        if self.knot_spacing is not None and not self.knot_spacing > 0:
            raise ValueError(f"knot_spacing must be positive seconds (or None: chosen per take), got {self.knot_spacing}")
        if not 0 <= self.refinements < len(self.widths_pos):
            raise ValueError(f"refinements must be in [0, {len(self.widths_pos) - 1}], got {self.refinements}")

    @classmethod
    def locked(cls, iterations: int = 12, reference_fps: float = REFERENCE_FPS) -> "Schedule":
        """The schedule once the initial alignment is locked on the rigid mode (rigidity
        discovered, or an actor's prior): no coarse widths or coarse splines to find the
        mode again, only the three finest widths on a spline with a knot per frame, whose
        motion is then smoothed with a cut-off chosen per take (facedyn.stabilize.smoothing),
        which smooths the tracking noise out of the skull's accelerations (the networks'
        input). Its velocity widths are 4x the paper's: with a knot per frame, the narrow
        ones made the solve follow the noise's high frequencies (their velocities are
        large), 10% acceleration error on a 9 Hz platform before smoothing, 6% with these.
        Starting over from 0.8 cm and a 4x coarser spline there moved the solve away from
        the alignment it started from and left 3-4x the error after 12 iterations a stage."""
        return cls(widths_pos=(0.2, 0.1, 0.05), widths_vel=(0.2, 0.1, 0.05), reference_fps=reference_fps,
                   iterations=iterations, knot_spacing=None, refinements=0)

    def stages(self) -> list[Stage]:
        return [
            Stage(k, float(wp), float(wv) * self.reference_fps, 1 <= k <= self.refinements)
            for k, (wp, wv) in enumerate(zip(self.widths_pos, self.widths_vel))
        ]

    def coarse_knots(self, first: int, frames: int, fps: float) -> np.ndarray:
        """Knots of the first stage's cubic spline over frames first..first+frames-1 of a take.

        Its inner knots lie on one grid for the whole take (every knot spacing x
        2^refinements from frame 0), clamped at the ends, so that a chunk of a long take
        is fitted in the same spline space as the whole take away from its ends, and its
        solve matches the whole take's where the chunks are blended.
        """
        coarse_frames = self.knot_spacing * fps * 2**self.refinements
        last = first + max(frames - 1, 1)
        grid = np.arange(math.floor(first / coarse_frames) + 1, math.ceil(last / coarse_frames)) * coarse_frames
        inner = grid[(grid > first + 1e-9) & (grid < last - 1e-9)]
        return np.concatenate([np.full(4, float(first)), inner, np.full(4, float(last))])
