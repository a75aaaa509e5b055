"""Plain captures for the stabilization benchmarks: what a tracker hands over, and back.

A simulated take's tracked points (world space, cm, Y up) are written as a plain USD mesh
cache the way trackers export them (metres, Z up, first frame 1001, no facedyn schema),
imported and stabilized with the console commands as a user runs them, and the solved
skull read back. The import turns metres/Z-up into facedyn's cm/Y-up, so the solved skull
is directly comparable with the simulator's truth.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np

FIRST_FRAME = 1001


def write_plain_cache(path: Path, world_cm: np.ndarray, counts, indices, fps: float) -> Path:
    """A mesh cache in metres, Z up: (x, y, z) cm Y-up -> (x, -z, y) / 100."""
    import facedyn.usd  # noqa: F401  (registers facedyn's schemas before the first stage is made)
    from pxr import Usd, UsdGeom, Vt

    stage = Usd.Stage.CreateNew(str(path))
    stage.SetTimeCodesPerSecond(fps)
    stage.SetFramesPerSecond(fps)
    stage.SetStartTimeCode(FIRST_FRAME)
    stage.SetEndTimeCode(FIRST_FRAME + len(world_cm) - 1)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.Xform.Define(stage, "/Tracked")
    mesh = UsdGeom.Mesh.Define(stage, "/Tracked/Face")
    stage.SetDefaultPrim(stage.GetPrimAtPath("/Tracked"))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray.FromNumpy(np.asarray(counts, np.int32)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray.FromNumpy(np.asarray(indices, np.int32)))
    attr = mesh.CreatePointsAttr()
    for i, frame in enumerate(world_cm):
        z_up = np.stack([frame[:, 0], -frame[:, 2], frame[:, 1]], axis=1) * 0.01
        attr.Set(Vt.Vec3fArray.FromNumpy(np.ascontiguousarray(z_up, np.float32)), FIRST_FRAME + i)
    stage.GetRootLayer().Save()
    return path


def usdfacedyn(*args: str) -> None:
    """Run the console command as a user would; a failure stops the benchmark with its message."""
    command = [sys.executable, "-m", "facedyn.cli", *args, "-q"]
    done = subprocess.run(command, capture_output=True, text=True)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed: {done.stderr.strip() or done.stdout.strip()}")


def stabilize_with_cli(cache: Path, folder: Path, actor: Path | None = None, fps: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """import (resampled to `fps` when given) + stabilize with the defaults (into `actor`'s skull frame when given); the
    solved skull (translate, orient) per frame."""
    from facedyn.usd.take import read_take

    usdfacedyn("import", str(cache), "-o", str(folder / "capture.usdc"), *(("--fps", f"{fps:g}") if fps else ()))
    usdfacedyn("stabilize", str(folder / "take.usda"), "-o", str(folder / "stabilized.usdc"), "--attach", str(folder / "take.usda"),
               *(("--actor", str(actor)) if actor is not None else ()))
    performance, _ = read_take(folder / "take.usda")
    return performance.skull_translate, performance.skull_orient


def imported_points(folder: Path) -> np.ndarray:
    """The imported capture's points (cm, Y up): what the arrays-only solves read."""
    from facedyn.usd.take import read_take

    performance, _ = read_take(folder / "capture.usdc")
    return performance.points
