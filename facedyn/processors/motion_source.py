"""Skull motion sources for synthesize and retarget: mocap, another take, or procedural.

Every source is brought to the target take's frame rate and length: resampled (slerp for
rotations), never silently misaligned; a source shorter than the take is an error.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from facedyn.errors import UsageError
from facedyn import motion

PROCEDURAL = ("still", "walk", "run", "hop")
MAX_PLATFORM_HZ = 100.0  # well above any tissue resonance; the simulated protocol uses 6-11 Hz


def skull_motion(source: str, fps: float, frame_count: int, joint: str = "Head", seed: int = 0, *,
                 bvh: dict | None = None) -> tuple[np.ndarray, np.ndarray, str]:
    """(translate (F,3), orient (F,4), description) of `source` at fps over frame_count frames.

    source: a BVH file, a take (.usda/.usdc with a solved skull), or walk | run | hop |
    still | platform:9hz (platform:4hz:side or :forward shakes horizontally). bvh: a BVH's
    `units` (cm per unit), `up` and `forward` axes where the file cannot tell (None: read
    from the file).
    """
    duration = frame_count / fps
    kind, _, arg = source.partition(":")
    if bvh and (source in PROCEDURAL or kind == "platform" or Path(source).suffix.lower().startswith(".usd")):
        flags = ", ".join(f"--bvh-{key}" for key in bvh)
        raise UsageError(f"{flags}: BVH conventions, but the skull motion {source!r} is not a BVH file")
    if source in PROCEDURAL:
        trajectory = getattr(motion, source)(duration_s=duration, fps=fps, seed=seed)
        return _fit(trajectory, frame_count, source)
    if kind == "platform":
        try:
            hz, axis = motion.parse_platform(arg)
        except ValueError as error:
            raise UsageError(f"--skull-motion: {error}") from None
        if not 0 < hz <= MAX_PLATFORM_HZ:  # NaN fails too
            raise UsageError(f"--skull-motion: a platform frequency must lie in (0, {MAX_PLATFORM_HZ:g}] Hz, got {source!r}")
        trajectory = motion.platform(hz, motion.PLATFORM_AMPLITUDE_CM, duration_s=duration, fps=fps, seed=seed, axis=axis)
        return _fit(trajectory, frame_count, source)
    path = Path(source)
    if not path.exists():
        raise UsageError(f"skull motion {source!r}: not a file, nor one of {', '.join(PROCEDURAL)}, platform:HZ[:{'|'.join(motion.PLATFORM_AXES)}]")
    if not path.suffix.lower().startswith(".usd"):  # anything but USD is read as mocap, which names what is wrong
        trajectory = motion.from_bvh(path, joint, **(bvh or {}))
        if trajectory.fps != fps:
            trajectory = motion.resample(trajectory, fps)
        if trajectory.frame_count < frame_count:
            raise UsageError(f"{path}: {trajectory.frame_count / fps:.2f} s of motion for a {duration:.2f} s take")
        return _fit(trajectory, frame_count, f"{path.name} joint {joint}")
    return _from_take(path, fps, frame_count)


def motion_files(source: str) -> list:
    """What of `source` a layer made with it records as its inputs, each identified by its content
    (facedyn.usd.runs), so an edit of the motion makes the layer stale: a BVH file; the layers a
    take composes (not its root's bytes, which change whenever a layer is attached to it);
    nothing for a procedural motion (its name and seed are parameters)."""
    path = Path(source) if source else None
    if path is None or not path.is_file():
        return []
    if not path.suffix.lower().startswith(".usd"):
        return [path.resolve()]
    from facedyn.usd.runs import read_elsewhere
    from facedyn.usd.stage import open_stage
    from facedyn.usd.take import read_inputs

    return read_elsewhere(read_inputs(open_stage(path)))


def _fit(trajectory: motion.SkullTrajectory, frame_count: int, description: str):
    return trajectory.translate[:frame_count].copy(), trajectory.orient[:frame_count].copy(), description


def _from_take(path: Path, fps: float, frame_count: int):
    from facedyn.usd.errors import TakeError
    from facedyn.usd.take import read_take

    perf, source = read_take(path)
    if perf.skull_orient is None:
        raise TakeError(f"{path}: {source.mesh_path} has no solved skull motion to take (stabilize it first)")
    trajectory = motion.SkullTrajectory(*perf.skull(), perf.fps)
    if perf.fps != fps:
        trajectory = motion.resample(trajectory, fps)
    if trajectory.frame_count < frame_count:
        raise TakeError(f"{path}: {trajectory.frame_count} frames of skull motion at {fps:g} fps for a {frame_count}-frame take")
    return _fit(trajectory, frame_count, f"skull of {path.name}")
