"""Mode pursuit on a long take: chunked solve, time and peak memory.

A 100,000-frame take (synthetic, known skull motion) is solved in overlapping chunks;
the record gives wall time, the error against the truth, the size of the input and of
the output (skull-space points, same size), and the peak of what the solve allocated
with NumPy beyond them (tracemalloc; OpenCL buffers are not counted, so use --backend
numpy for the memory figure), which is bounded by the chunk size, not the take.

    python benchmarks/bench_stabilize_long.py [--frames 100000] [--vertices 300] [--chunk 4096] [--out FILE] [--note TEXT]

Prints one JSON object.
"""
from __future__ import annotations

import time
import tracemalloc

import numpy as np

from facedyn.stabilize import stabilize
from facedyn.stabilize.synthetic import synthetic_take

from harness import Recorder, parser


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--frames", type=int, default=100_000)
    arguments.add_argument("--vertices", type=int, default=300)
    arguments.add_argument("--chunk", type=int, default=4096)
    arguments.add_argument("--overlap", type=int, default=128)
    arguments.add_argument("--backend", default="auto", choices=("auto", "numpy", "opencl"))
    args = arguments.parse_args()
    record = Recorder("bench_stabilize_long", args)  # made before measuring: it notes the commit measured
    take = synthetic_take(frames=args.frames, vertices=args.vertices, fps=120.0, seed=7)
    skull = take.skull.astype(np.float32)
    del take.skull
    tracemalloc.start()
    start = time.perf_counter()
    result = stabilize(
        take.world, take.fps, rest=take.rest, backend=args.backend, chunk_frames=args.chunk, chunk_overlap=args.overlap
    )
    seconds = time.perf_counter() - start
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    error = np.linalg.norm(result.skull_points - skull, axis=-1)
    with record:
        record({
            "case": f"long {args.frames}x{args.vertices}",
            "frames": args.frames,
            "vertices": args.vertices,
            "chunk_frames": args.chunk,
            "chunk_overlap": args.overlap,
            "backend": result.backend,
            "seconds": round(seconds, 2),
            "timings": {k: round(v, 2) for k, v in result.timings.items()},
            "vertex_frames_per_second": round(args.frames * args.vertices / seconds),
            "input_mb": round(take.world.nbytes / 2**20, 1),
            "output_points_mb": round(result.skull_points.nbytes / 2**20, 1),
            "solve_peak_numpy_mb_beyond_output": round((peak - result.skull_points.nbytes) / 2**20, 1),
            "median_error_cm": float(np.median(error)),
            "mean_error_cm": float(error.mean()),
            "energy": result.energy,
        })


if __name__ == "__main__":
    main()
