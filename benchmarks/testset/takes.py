"""What each test-set take performs: skull motion and expression curves, at the simulator's rate.

Held expressions are held the way a person holds one: neutral, an ease-in of 0.3-0.6 s
(drawn per take), a hold that drifts slowly (+-8 % of the pose, under 0.5 Hz) with small
micro-motion (2-5 Hz, 2 % of full weight), and an ease-out over the last 0.4 s. Dialogs are
Live Link Face curves from a window drawn per take. Skull motion is facedyn.motion's
platform (vertical or sideways) or a CMU head trajectory, optionally played faster
(`bvh:FILE@1.6`: a walk at 1.6x cadence stands in for a run: the shared data has no run).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from facedyn import motion
from facedyn.geometry import quaternion
from facedyn.performance import SkullTrajectory

LEAD_S = 0.5  # simulated before the first captured frame: the start-up transient dies out there

# The session's held expressions (ARKit names; a shape the rig lacks is left out).
HELD = {
    "smile": {"mouthSmile_L": 0.8, "mouthSmile_R": 0.75},
    "jaw_open": {"jawOpen": 0.45},
    "brow_raise": {"browInnerUp_L": 0.8, "browInnerUp_R": 0.8, "browOuterUp_L": 0.7, "browOuterUp_R": 0.7},
    "pucker": {"mouthPucker": 0.8},
    "cheek_puff": {"cheekPuff_L": 0.7, "cheekPuff_R": 0.7, "cheekPuff": 0.7},
    "frown": {"mouthFrown_L": 0.7, "mouthFrown_R": 0.7, "browDown_L": 0.5, "browDown_R": 0.5},
    "sneer": {"noseSneer_L": 0.7, "noseSneer_R": 0.7, "mouthUpperUp_L": 0.4, "mouthUpperUp_R": 0.4},
    "funnel": {"mouthFunnel": 0.7, "jawOpen": 0.15},
    "squint": {"eyeSquint_L": 0.7, "eyeSquint_R": 0.7, "eyeBlink_L": 0.2, "eyeBlink_R": 0.2},
    "jaw_side": {"jawLeft": 0.5, "mouthStretch_L": 0.3},
    "stretch": {"mouthStretch_L": 0.6, "mouthStretch_R": 0.6, "jawOpen": 0.1},
}


@dataclass(frozen=True)
class TakeRecipe:
    """One take: `kind` is "session" (held expressions, for calibration), "test", "transfer"
    (one test take's expression under another's skull motion: the truth that synthesis and
    retargeting are scored against; `sources` names the two, expression first) or "cross"
    (a transfer whose motion is another actor's test take: its source named ACTOR/TAKE)."""

    name: str
    kind: str
    motion: str  # platform:HZ[:side|up|forward] | bvh:FILE[@SPEED] (FILE in the shared cmu-mocap folder)
    expression: str | None = None  # a HELD key
    dialog: str | None = None  # a Live Link CSV in the shared livelink-face folder
    duration_s: float = 3.0
    seed: int = 0
    motion_seed: int | None = None  # the skull trajectory's seed (None: `seed`)
    sources: tuple[str, ...] = ()  # a transfer take's (expression take, motion take); a cross take's motion take is ACTOR/TAKE
    motion_scale: float = 1.0  # the skull motion's size about its steady path (1: as recorded; testset_static.py varies it)

    @property
    def skull_seed(self) -> int:
        return self.seed if self.motion_seed is None else self.motion_seed


def skull_trajectory(recipe: TakeRecipe, data: Path, fps: float) -> SkullTrajectory:
    """LEAD_S + duration_s of the recipe's skull motion at `fps` (cm, Y up), scaled by its motion_scale."""
    trajectory = _recorded_trajectory(recipe, data, fps)
    return trajectory if recipe.motion_scale == 1.0 else scaled_about_steady_path(trajectory, recipe.motion_scale)


def scaled_about_steady_path(trajectory: SkullTrajectory, scale: float) -> SkullTrajectory:
    """The motion `scale` times as large: the translation about its straight-line fit (steady travel has no
    acceleration, so it stays), the rotation about its mean orientation."""
    frames = np.arange(len(trajectory.translate))
    steady = np.stack([np.polyval(np.polyfit(frames, axis, 1), frames) for axis in trajectory.translate.T], axis=1)
    mean = quaternion.from_rotvec(quaternion.to_rotvec(trajectory.orient).mean(axis=0))
    means = np.broadcast_to(mean, trajectory.orient.shape)
    turn = quaternion.to_rotvec(quaternion.multiply(quaternion.conjugate(means), trajectory.orient))
    orient = quaternion.multiply(means, quaternion.from_rotvec(scale * turn))
    return SkullTrajectory(steady + scale * (trajectory.translate - steady), orient, trajectory.fps)


def _recorded_trajectory(recipe: TakeRecipe, data: Path, fps: float) -> SkullTrajectory:
    seconds = LEAD_S + recipe.duration_s
    kind, _, arg = recipe.motion.partition(":")
    if kind == "platform":
        hz, axis = motion.parse_platform(arg)
        return motion.platform(hz, motion.PLATFORM_AMPLITUDE_CM, duration_s=seconds, fps=fps, seed=recipe.skull_seed, axis=axis)
    if kind == "bvh":
        name, _, speed = arg.partition("@")
        speed = float(speed or 1.0)
        # seconds * speed of the capture sampled every speed / fps s, played back every 1 / fps s: `speed` times faster
        played = motion.from_bvh(data / "cmu-mocap" / name, "Head", duration_s=seconds * speed, fps=fps / speed, seed=recipe.skull_seed)
        return SkullTrajectory(played.translate, played.orient, fps)
    raise ValueError(f"take {recipe.name}: unknown motion {recipe.motion!r} (platform:HZ or bvh:FILE[@SPEED])")


def expression_weights(recipe: TakeRecipe, names: tuple[str, ...], data: Path, fps: float, frames: int) -> np.ndarray:
    """(frames, K) weights at `fps` for the rig's expression `names`."""
    rng = np.random.default_rng(recipe.seed + 7)
    weights = np.zeros((frames, len(names)), np.float64)
    if recipe.dialog is not None:
        from facedyn.io.livelink import read_livelink_csv
        from facedyn.io.resample import resample_curves

        curves = resample_curves(read_livelink_csv(data / "livelink-face" / recipe.dialog, names), fps)
        start = int(rng.integers(0, max(len(curves.weights) - frames, 0) + 1))
        rows = np.minimum(np.arange(start, start + frames), len(curves.weights) - 1)
        weights[:, [names.index(n) for n in curves.names]] = curves.weights[rows]
        return weights
    if recipe.expression is None:
        return weights
    t = np.arange(frames) / fps
    ease_in = rng.uniform(0.3, 0.6)
    start = LEAD_S + rng.uniform(0.1, 0.3)
    up = _smoothstep((t - start) / ease_in)
    down = 1.0 - _smoothstep((t - (t[-1] - 0.4)) / 0.4)
    for shape, value in HELD[recipe.expression].items():
        if shape not in names:
            continue
        drift = 1.0 + 0.08 * _band_noise(rng, t, 0.1, 0.5)
        micro = 0.02 * _band_noise(rng, t, 2.0, 5.0)
        weights[:, names.index(shape)] = np.clip(value * drift * up * down + micro * up * down, 0.0, 1.0)
    return weights


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def _band_noise(rng, t: np.ndarray, low_hz: float, high_hz: float, waves: int = 6) -> np.ndarray:
    """A smooth random signal of unit RMS: a few sinusoids between low_hz and high_hz."""
    hz = rng.uniform(low_hz, high_hz, waves)
    phase = rng.uniform(0, 2 * np.pi, waves)
    return np.sin(2 * np.pi * hz[None] * t[:, None] + phase).sum(axis=1) * np.sqrt(2.0 / waves)
