"""Mode pursuit: fast solver vs the PyTorch reference, side by side in one run.

Cases are the paper's timing table sizes (papers/001, Table I): 651 frames x 1,185 vertices
and 63 x 2,466, at 12 and 24 L-BFGS iterations per stage, on synthetic takes with known
skull motion (facedyn.stabilize.synthetic), so accuracy is reported beside speed. The fast
solver runs with each energy backend (NumPy, and OpenCL where a device exists), timed
warm (program built by a first, discarded run) as the best of --repeat runs; the
reference runs once per case, with --torch-threads intra-op threads (default 1: on a
small shared machine PyTorch's threads spin-wait against other processes and made the
reference 10-100x slower and erratic, which would flatter the fast solver). Times are
whole stabilize() calls (initialization by robust ICP included); "solve" is the stage
loop alone.

    python benchmarks/bench_stabilize_speed.py [--repeat 3] [--torch-threads 1] [--skip-reference] [--out FILE] [--note TEXT]

Prints one JSON object per case (the OpenCL device in ``device``, the machine in the record's context).
"""
from __future__ import annotations

import time

import numpy as np
import torch

from facedyn.kernels import runtime
from facedyn.stabilize import Schedule, stabilize
from facedyn.stabilize.synthetic import synthetic_take

from harness import Recorder, parser

CASES = [(651, 1185, 12), (651, 1185, 24), (63, 2466, 12), (63, 2466, 24)]
FPS = 120.0


def median_error(result, take) -> float:
    return float(np.median(np.linalg.norm(result.skull_points - take.skull, axis=-1)))


def run(take, iterations: int, solver: str, backend: str = "numpy"):
    schedule = Schedule(iterations=iterations)
    start = time.perf_counter()
    result = stabilize(take.world, take.fps, rest=take.rest, solver=solver, backend=backend, schedule=schedule)
    return result, time.perf_counter() - start


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--repeat", type=int, default=3, help="fast-solver runs per case and backend (best is reported)")
    arguments.add_argument("--torch-threads", type=int, default=1, help="PyTorch intra-op threads for the reference")
    arguments.add_argument("--skip-reference", action="store_true")
    args = arguments.parse_args()
    with Recorder("bench_stabilize_speed", args) as record:
        measure(args, record)


def measure(args, record: Recorder) -> None:
    """Each case of CASES: three-point, the fast solver per backend and (unless skipped) the reference."""
    torch.set_num_threads(args.torch_threads)
    backends = ["numpy"] + (["opencl"] if runtime.available() else [])
    warm = synthetic_take(frames=120, vertices=300, fps=FPS, seed=99)
    for backend in backends:
        run(warm, 2, "fast", backend)  # builds the OpenCL program, warms caches
    for frames, vertices, iterations in CASES:
        take = synthetic_take(frames=frames, vertices=vertices, fps=FPS, seed=frames + vertices)
        three = stabilize(take.world, take.fps, method="three-point", rest=take.rest, three_point=take.three_point)
        fields = {
            "case": f"{frames}x{vertices}@{iterations}",
            "frames": frames,
            "vertices": vertices,
            "iterations_per_stage": iterations,
            "fps": FPS,
            "device": runtime.describe() if runtime.available() else "no OpenCL",
            "torch_threads": torch.get_num_threads(),
            "three_point_median_error_cm": median_error(three, take),
        }
        for backend in backends:
            runs = [run(take, iterations, "fast", backend) for _ in range(args.repeat)]
            fast, seconds = min(runs, key=lambda r: r[1])
            fields[f"fast_{backend}"] = {
                "seconds": round(seconds, 4),
                "seconds_all_runs": [round(r[1], 4) for r in runs],
                "solve_seconds": round(fast.timings["solve"], 4),
                "init_seconds": round(fast.timings["init"], 4),
                "evaluations": sum(h.evaluations for h in fast.history),
                "energy": fast.energy,
                "median_error_cm": median_error(fast, take),
            }
        if not args.skip_reference:
            ref, ref_seconds = run(take, iterations, "reference")
            fields["reference"] = {
                "seconds": round(ref_seconds, 3),
                "solve_seconds": round(ref.timings["solve"], 3),
                "evaluations": sum(h.evaluations for h in ref.history),
                "energy": ref.energy,
                "median_error_cm": median_error(ref, take),
            }
            for backend in backends:
                fast = fields[f"fast_{backend}"]
                fast["speedup"] = round(ref_seconds / fast["seconds"], 1)
                fast["solve_speedup"] = round(ref.timings["solve"] / fast["solve_seconds"], 1)
                fast["energy_relative_to_reference"] = (fast["energy"] - ref.energy) / ref.energy
        record(fields)


if __name__ == "__main__":
    main()
