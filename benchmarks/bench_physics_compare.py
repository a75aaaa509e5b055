"""The two physics side by side on the built-in face: true dynamics and speed.

For each take (a 9 Hz platform, CMU walk 131_01 when the shared data is there, the
procedural run), both facedyn.sim.tissue (springs + membrane, the training simulator)
and facedyn.sim.volumetric (the hyperelastic layer, the test simulator) simulate the same
quasistatic skin (held jaw-open) under the same true skull motion, with default
parameters. Prints one JSON object per take and physics: the true dynamics' RMS and peak
over the face region (mm), the frequency of the face's summed dynamics spectrum peak
(Hz), and seconds per frame (wall clock, this machine).

    .venv/bin/python benchmarks/bench_physics_compare.py [--seconds 5] [--data ../shared/data] [--out FILE] [--note TEXT]
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from facedyn.sim import tissue, volumetric
from facedyn.sim.corpus import TakeSpec, expression_weights, skull_motion
from facedyn.sim.default_face import default_face

from harness import Recorder, parser

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def spectrum_peak_hz(dynamics: np.ndarray, fps: float) -> float:
    """Frequency of the largest peak of the power spectrum summed over every vertex and axis."""
    signal = dynamics.reshape(len(dynamics), -1).astype(np.float64)
    signal = signal - signal.mean(axis=0)
    n = 8 * len(signal)
    power = (np.abs(np.fft.rfft(signal * np.hanning(len(signal))[:, None], n, axis=0)) ** 2).sum(axis=1)
    return float(np.fft.rfftfreq(n, 1 / fps)[np.argmax(power)])


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--seconds", type=float, default=5.0, help="take length (s), default 5 (600 frames)")
    arguments.add_argument("--data", type=Path, default=DATA, help="shared data folder (for CMU 131_01)")
    args = arguments.parse_args()
    rig = default_face()
    takes = [TakeSpec("platform9hz", "platform:9", "jaw_open", duration_s=args.seconds, seed=1),
             TakeSpec("run", "run", "jaw_open", duration_s=args.seconds, seed=2)]
    walk = args.data / "cmu-mocap" / "131_01.bvh"
    if walk.is_file():
        takes.insert(1, TakeSpec("cmu_walk_131_01", f"bvh:{walk}", "jaw_open", duration_s=args.seconds, seed=3))
    face = rig.face_vertices
    with Recorder("bench_physics_compare", args) as record:
        for spec in takes:
            trajectory = skull_motion(spec)
            y = rig.evaluate(expression_weights(rig, spec, trajectory.frame_count))
            skip = int(0.5 * spec.fps)  # past the expression's ease-in
            for name, physics in (("tissue", tissue), ("volumetric", volumetric)):
                started = time.perf_counter()
                result = physics.simulate(y, rig.topology.triangles(), trajectory.translate, trajectory.orient, spec.fps,
                                          rigid_weights=rig.rigid_weights, neutral=rig.neutral)
                seconds = time.perf_counter() - started
                dynamics = result.dynamics[skip:, face]
                magnitude = np.linalg.norm(dynamics, axis=-1)
                record({
                    "case": f"{spec.name}, {name} physics", "take": spec.name, "physics": name,
                    "frames": trajectory.frame_count, "points": rig.point_count,
                    "rms_mm": round(float(np.sqrt(np.mean(magnitude**2))) * 10, 3),
                    "peak_mm": round(float(magnitude.max()) * 10, 3),
                    "spectrum_peak_hz": round(spectrum_peak_hz(dynamics, spec.fps), 2),
                    "seconds_per_frame": round(seconds / trajectory.frame_count, 4),
                    "seconds": round(seconds, 2),
                })


if __name__ == "__main__":
    main()
