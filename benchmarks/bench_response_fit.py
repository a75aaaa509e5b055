"""Time of fitting an actor's linear response on a calibration session, its ridge chosen by
cross-validation (facedyn.dynamics.response.fit_linear_response, as `train-synthesis
--response linear` and `usdfacedyn calibrate` run it).

The session is built at array level, so that it takes seconds rather than the simulator's
hours: a 2,700-point curved sheet (54 x 50) with a rigid top band, 344 skin samples and the
default five landmarks, and TAKES takes of 4.5 s at 120 fps, each one held expression (a
smooth offset of the sheet) under a platform at 5-11 Hz or a gait-like mix of frequencies,
its skin answering the skull's acceleration through a damped oscillator whose gain varies
over the face, plus 0.05 mm of tracking noise. Speed does not depend on what the skin does;
the figure printed beside it (the session's motion the left-out responses leave) says the
fit saw a response to find.

Prints one JSON object per case: takes, ridges, seconds (wall and the process's CPU: on a
shared machine the second says more), the chosen ridge and its figure.

    python benchmarks/bench_response_fit.py [--takes 70] [--ridge R] [--module facedyn.dynamics.response] [--out FILE] [--note TEXT]
"""
from __future__ import annotations

import argparse
import importlib
import os
import time

import numpy as np
from bench_remove_speed import sheet
from harness import Recorder, parser

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.modelfile import DynamicsModel
from facedyn.dynamics.network import SYNTHESIS_HIDDEN, Network, NetworkSpec
from facedyn.dynamics.skull_motion import SkullMotionInput
from facedyn.dynamics.training_sequence import TrainingSequence
from facedyn.geometry import quaternion

ROWS, COLS, FPS, SAMPLES, SECONDS = 54, 50, 120.0, 344, 4.5


def session(points: np.ndarray, count: int) -> list[TrainingSequence]:
    """`count` held-expression takes in skull space (see the module's docstring)."""
    rng = np.random.default_rng(0)
    frames = int(SECONDS * FPS)
    t = np.arange(frames) / FPS
    gain = 0.002 * (1.0 + (points[:, 1] < 0)) * (1 + 0.5 * np.sin(points[:, 0] / 4))  # cm per cm/s^2, softer below
    omega, zeta = 2 * np.pi * 6.0, 0.2
    takes = []
    for k in range(count):
        if k % 2:
            hz = 5 + 6 * rng.random()
            vertical = 0.4 * np.sin(2 * np.pi * hz * t)
        else:
            vertical = sum(rng.uniform(0.2, 1.0) * np.sin(2 * np.pi * f * t + rng.uniform(0, 6)) for f in rng.uniform(1, 12, 4))
        translate = np.stack([0.3 * np.sin(0.7 * t + k), 160 + vertical, 0.5 * t], 1)
        orient = quaternion.from_rotvec(np.stack([0.05 * np.sin(1.3 * t + k), 0.2 * np.sin(0.5 * t + 2 * k), 0 * t], 1))
        acc = np.gradient(np.gradient(vertical, t), t)
        y = np.zeros(frames)  # x'' + 2 zeta omega x' + omega^2 x = -a, semi-implicit Euler
        v = 0.0
        for i in range(1, frames):
            v += (-acc[i] - 2 * zeta * omega * v - omega ** 2 * y[i - 1]) / FPS
            y[i] = y[i - 1] + v / FPS
        held = 0.3 * rng.standard_normal(3) * (points[:, 1:2] < 0) * np.sin(points[:, 0:1] / 5 + k)
        skin = points[None] + held[None] + (omega ** 2 * gain)[None, :, None] * y[:, None, None] * np.array([0.0, 1.0, 0.2])
        skin += rng.normal(0, 0.005, skin.shape)
        takes.append(TrainingSequence(f"take{k:03d}", skin.astype(np.float32), FPS, translate, orient, space="skull"))
    return takes


def main() -> None:
    arguments = parser(__doc__)
    arguments.description, arguments.formatter_class = __doc__, argparse.RawDescriptionHelpFormatter  # --help shows the whole docstring
    arguments.add_argument("--takes", type=int, default=70)
    arguments.add_argument("--ridge", type=float, default=None, help="one ridge given (default: the session chooses among RIDGES)")
    arguments.add_argument("--module", default="facedyn.dynamics.response", help="the module whose fit_linear_response to time")
    args = arguments.parse_args()
    record = Recorder("bench_response_fit", args)  # made before measuring: it notes the commit measured
    fit_linear_response = importlib.import_module(args.module).fit_linear_response
    points, topology, rigid = sheet(ROWS, COLS, rigid_rows=6)
    face = FaceSetup.build(topology, points, rigid_vertices=rigid, sample_count=SAMPLES)
    motion = SkullMotionInput()
    spec = NetworkSpec(len(face.landmarks) * motion.width * 3 + 2 * len(face.samples), SYNTHESIS_HIDDEN, 3 * len(face.samples))
    template = DynamicsModel("synthesis", Network(spec), face, FPS, {"stretch_smoothing": 10}, skull_motion=motion)
    takes = session(points, args.takes)
    start, cpu = time.perf_counter(), time.process_time()
    model = fit_linear_response(template, takes, ridge=args.ridge)
    seconds, cpu = time.perf_counter() - start, time.process_time() - cpu
    calibration = model.info["calibration"]
    with record:
        record({"case": "linear response fit, ridge cross-validated", "module": args.module, "takes": args.takes,
                "points": len(points), "samples": len(face.samples), "rows": calibration["rows"], "ridges": len(calibration["ridge_candidates"]),
                "seconds": round(seconds, 1), "cpu_seconds": round(cpu, 1), "ridge": calibration["ridge"],
                "session_cross_validated_left": calibration["session_cross_validated_left"],
                "ridge_candidates": calibration["ridge_candidates"], "cpu_count": os.cpu_count()})


if __name__ == "__main__":
    main()
