"""Stretch features speed: 1,000 frames x 344 samples on the ICT rig, per backend.

The frames are random expressions of the ICT rig (../shared/data), or of a synthetic
11,248-point sheet where the rig is absent. Prints one JSON object per backend: the best
of a few runs after a warm-up (the machine's cores are shared), in seconds and frames/s.

    python benchmarks/bench_stretch.py [--frames 1000] [--samples 344] [--repeats 3] [--out FILE] [--note TEXT]
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from facedyn.dynamics.samples import farthest_point_samples
from facedyn.dynamics.stretch import UVNeighbourhoods, difference_lengths, stretch_features
from facedyn.kernels import runtime
from facedyn.performance import Topology, UVs

from harness import Recorder, parser

ICT_RIG = Path(__file__).resolve().parents[2] / "shared" / "data" / "ict-facekit" / "ict_face_rig.usdc"


def ict_frames(frames: int, samples: int):
    from facedyn.usd.blendshape_rig import read_blendshape_rig

    rig = read_blendshape_rig(ICT_RIG)
    chosen = farthest_point_samples(rig.neutral, rig.topology.triangles(), samples, rig.face_vertices)
    weights = np.random.default_rng(0).uniform(0.0, 0.5, (frames, rig.expression_count))
    return "ict", rig.topology, rig.uvs, rig.neutral, chosen, rig.evaluate(weights)


def synthetic_frames(frames: int, samples: int):
    """A gently curved 148 x 76 sheet (11,248 points, 2 mm quads) breathing in and out."""
    nx, ny = 148, 76
    ys, xs = np.mgrid[0:ny, 0:nx]
    uv = np.stack([xs.ravel() / (nx - 1), ys.ravel() / (ny - 1)], axis=1)
    x, y = 0.2 * xs.ravel(), 0.2 * ys.ravel()
    neutral = np.stack([x, y, 0.02 * (x - 15.0) ** 2], axis=1).astype(np.float32)
    a = (np.arange(ny - 1)[:, None] * nx + np.arange(nx - 1)[None, :]).ravel()
    quads = np.stack([a, a + 1, a + nx + 1, a + nx], axis=1)
    topology = Topology(np.full(len(quads), 4, np.int32), quads.ravel().astype(np.int32))
    phase = np.sin(np.linspace(0.0, 20.0, frames))[:, None, None]
    points = neutral[None] * (1.0 + 0.05 * phase * np.array([1.0, 0.5, 0.0], np.float32))
    chosen = np.random.default_rng(0).choice(len(neutral), samples, replace=False)
    return "synthetic", topology, UVs(uv.astype(np.float32), None, "vertex"), neutral, chosen, points.astype(np.float32)


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--frames", type=int, default=1000)
    arguments.add_argument("--samples", type=int, default=344)
    arguments.add_argument("--repeats", type=int, default=3)
    args = arguments.parse_args()
    make = ict_frames if ICT_RIG.is_file() else synthetic_frames
    mesh, topology, uvs, neutral, samples, points = make(args.frames, args.samples)
    started = time.perf_counter()
    neighbourhoods = UVNeighbourhoods.build(topology, uvs, neutral, samples)
    build_seconds = time.perf_counter() - started
    rest = difference_lengths(neutral, neighbourhoods)
    backends = ["numpy"] + (["opencl"] if runtime.available() else [])
    with Recorder("bench_stretch", args) as record:
        for backend in backends:
            stretch_features(points, neighbourhoods, rest, backend=backend)  # warm-up: program build, first touch
            times = []
            for _ in range(args.repeats):
                started = time.perf_counter()
                stretch_features(points, neighbourhoods, rest, backend=backend)
                times.append(time.perf_counter() - started)
            seconds = min(times)
            fields = {
                "case": "stretch features", "backend": backend, "mesh": mesh, "frames": args.frames,
                "samples": neighbourhoods.sample_count, "points": points.shape[1], "seconds": round(seconds, 4),
                "frames_per_s": round(args.frames / seconds, 1), "neighbourhoods_build_seconds": round(build_seconds, 3),
            }
            if backend == "opencl":
                fields["device"] = runtime.describe()
            record(fields)


if __name__ == "__main__":
    main()
