"""Long takes in bounded memory: a 4,058-point take of 10,000 and 50,000 frames through the pipeline.

The capture is made cheaply: the simulator runs a short take of the built-in face (a smile
while walking), whose true skull-space skin is looped back and forth (no jumps) under a
procedural skull motion as long as the take, and written as the take's capture layer
chunk by chunk (value clips past 5,000 frames, as `import` would write it). Tiny removal
and synthesis models (1 epoch, their accuracy is not what is measured) are trained on the
short take. Then each step runs as its own `usdfacedyn` process: stabilize, remove,
synthesize (and import of a mesh cache, up to --import-max-frames), and its peak RSS is
the process's VmHWM. Stabilize's throughput is vertex-frames per second of the step's wall
time. At the first frame count the streamed (chunked) stabilize is compared with the
unchunked solve of the same take (the same rest and rigid mask, the take's own).

    python benchmarks/bench_long_take.py [--frames 10000 50000] [--workdir DIR] [--keep] [--out FILE] [--note TEXT]

Prints one JSON object per frame count (and one for the chunked/unchunked comparison).
Disk: about 0.25 MB per frame for the capture and stabilized layers and 0.5 MB for each of
quasistatic and synthesized (50,000 frames: about 15 GB); removed afterwards unless --keep.
"""
from __future__ import annotations

import contextlib
import io
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from harness import Recorder, parser
from spill import work_folder, work_folder_arguments

STEP = """
import sys
from facedyn.cli import main
code = main(sys.argv[1:])
status = open("/proc/self/status").read().split("\\n")
peak = next(line.split()[1] for line in status if line.startswith("VmHWM"))
print("VMHWM_KB", peak, file=sys.stderr)
sys.exit(code)
"""


def run_step(*argv) -> dict:
    """One usdfacedyn command in its own process: seconds, peak RSS (MB), exit code."""
    start = time.perf_counter()
    done = subprocess.run([sys.executable, "-c", STEP, *map(str, argv), "-q"], capture_output=True, text=True)
    seconds = time.perf_counter() - start
    peak = [line.split()[1] for line in done.stderr.splitlines() if line.startswith("VMHWM_KB")]
    if done.returncode != 0:
        raise SystemExit(f"{argv[0]} failed: {done.stderr.strip().splitlines()[-2:]}")
    return {"seconds": round(seconds, 1), "peak_rss_mb": round(int(peak[0]) / 1024, 1)}


def short_take(folder: Path, fps: float, train: bool = True):
    """The simulated short take (built-in face) and (with `train`) tiny F and H trained on it."""
    from facedyn.cli import main
    from facedyn.sim.corpus import TakeSpec
    from facedyn.sim.default_face import default_face
    from facedyn.processors.corpus_writer import build_corpus

    build_corpus(folder / "corpus", default_face(), [TakeSpec("base", "walk", "smile", duration_s=3.0, seed=1, fps=fps)])
    models = folder / "models"
    quiet = ["--json"]
    if train:
        with contextlib.redirect_stdout(io.StringIO()):  # their JSON reports are not this benchmark's output
            _train(main, folder, models, quiet)
    return folder / "corpus" / "base", models


def _train(main, folder: Path, models: Path, quiet: list[str]) -> None:
    assert main(["train-removal", str(folder / "corpus"), "-o", str(models / "f.removal"), "--skull", "truth",
                 "--epochs", "1", "--samples", "64", *quiet]) == 0
    assert main(["train-synthesis", str(folder / "corpus"), "-o", str(models / "h.synthesis"), "--quasistatic",
                 str(models / "f.removal"), "--skull", "truth", "--epochs", "1", *quiet]) == 0


def looped(count: int, period: int) -> np.ndarray:
    """Frame indices 0, 1, ..., period-1, period-2, ..., 0, 1, ...: a short take played back and forth."""
    cycle = np.concatenate([np.arange(period), np.arange(period - 2, 0, -1)])
    return cycle[np.arange(count) % len(cycle)]


def write_capture(take_folder: Path, base: Path, frames: int, chunk: int = 1024):
    """A `frames`-long capture layer + take root from the short take, written chunk by chunk.

    Returns the root and a function giving the true skull-space skin of frames a..b-1.
    """
    from facedyn.processors.motion_source import skull_motion
    from facedyn.geometry import quaternion
    from facedyn.usd import layers, schema
    from facedyn.usd.corpus_files import read_truth
    from facedyn.usd.take import read_take

    capture, source = read_take(base / "capture.usdc")
    truth = read_truth(base)
    skin = (truth.points + truth.offsets).astype(np.float32)  # true skull-space skin, y + u
    translate, orient, _ = skull_motion("walk", capture.fps, frames, seed=5)
    rotation = quaternion.to_matrix(orient).astype(np.float32)
    codes = np.arange(1001, 1001 + frames, dtype=np.float64)
    order = looped(frames, len(skin))

    def chunks():
        for a in range(0, frames, chunk):
            b = min(frames, a + chunk)
            world = np.einsum("fij,fnj->fni", rotation[a:b], skin[order[a:b]]) + translate[a:b, None, :].astype(np.float32)
            yield layers.LayerContent(frames=codes[a:b], points=world)

    face = schema.FaceAttributes(role="captured", rest_points=capture.rest_points, rigid_weights=capture.rigid_weights,
                                 face_vertices=capture.face_vertices, skin_samples=capture.skin_samples,
                                 alignment_vertices=capture.alignment_vertices)
    content = layers.LayerContent(frames=codes, mesh_path=source.mesh_path, skull_path=source.skull_path, face=face,
                                  skull=schema.SkullAttributes(landmarks=capture.landmarks), topology=capture.topology,
                                  uvs=capture.uvs)
    timing = source.timing.with_frames(codes[0], codes[-1])
    provenance = schema.Provenance(processor="import", version="bench_long_take", parameters={"frames": frames},
                                   frame_range=(codes[0], codes[-1]), inputs=[], role="captured")
    take_folder.mkdir(parents=True, exist_ok=True)
    path = layers.write_layer(take_folder / "capture.usdc", content, timing, provenance, define=True, chunks=chunks())
    return layers.write_take_root(take_folder / "take.usda", [path], timing), lambda a, b: skin[order[a:b]]


def chunked_vs_unchunked(root: Path, truth: np.ndarray, stabilized: Path) -> dict:
    """The streamed stabilize (overlapping chunks) against one solve of the whole take, both against the truth.

    truth: (F, N, 3) the true skull-space skin the capture was made from; stabilized: the streamed step's layer.
    """
    from facedyn.stabilize.api import stabilize
    from facedyn.usd.frames import TakeFrames
    from facedyn.usd.take import read_layers

    capture = TakeFrames(root, "stabilized")
    whole = capture.read(0, capture.frame_count)
    unchunked = stabilize(whole.world_points(), whole.fps, rest=whole.rest_points,
                          weights=whole.rigid_weights.astype(np.float64), chunk_frames=capture.frame_count)
    del whole
    chunked = read_layers([stabilized, stabilized.parent / "capture.usdc"]).points  # the streamed solve's skull-space skin
    difference = np.linalg.norm(chunked - unchunked.skull_points, axis=-1).max(axis=1)  # per frame, the largest
    errors = {"chunked": np.linalg.norm(chunked - truth, axis=-1), "unchunked": np.linalg.norm(unchunked.skull_points - truth, axis=-1)}

    def summary(values: np.ndarray) -> dict:
        return {"median": round(float(np.median(values)), 5), "mean": round(float(values.mean()), 5),
                "p99": round(float(np.percentile(values, 99)), 5)}

    return {"case": f"chunked vs unchunked stabilize, {capture.frame_count} frames",
            "frame_largest_vertex_difference_cm": {**summary(difference), "max": round(float(difference.max()), 5),
                                                   "frame_of_max": int(difference.argmax())},
            "vertex_error_vs_truth_cm": {name: summary(e) for name, e in errors.items()},
            "unchunked_seconds": round(unchunked.timings["total"], 1), "target_cm": 0.001,
            "how": "the take's given rest and rigid mask, fast solver; streamed: stabilize's default chunks; "
                   "truth: the simulated skull-space skin"}


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--frames", type=int, nargs="+", default=[10_000, 50_000])
    arguments.add_argument("--fps", type=float, default=120.0)
    work_folder_arguments(arguments)
    arguments.add_argument("--compare", action="store_true", help="also compare chunked and unchunked stabilize at the first count")
    arguments.add_argument("--compare-only", action="store_true", help="only stabilize, and compare it with the unchunked solve")
    args = arguments.parse_args()
    with work_folder("long_take.", args) as work, Recorder("bench_long_take", args) as record:
        base, models = short_take(work, args.fps, train=not args.compare_only)
        for k, frames in enumerate(args.frames):
            take = work / f"take_{frames}"
            start = time.perf_counter()
            root, truth = write_capture(take, base, frames)
            points = truth(0, 1).shape[1]
            fields = {"case": f"long take {frames} frames", "frames": frames, "points": points,
                      "capture_write_seconds": round(time.perf_counter() - start, 1)}
            steps = {}
            steps["stabilize"] = run_step("stabilize", root, "-o", take / "stabilized.usdc", "--attach", root)
            if not args.compare_only:
                steps["remove"] = run_step("remove", root, "-o", take / "quasistatic.usdc", "--model", models / "f.removal",
                                           "--attach", root)
                steps["synthesize"] = run_step("synthesize", root, "-o", take / "synthesized.hop.usdc", "--model",
                                               models / "h.synthesis", "--skull-motion", "hop", "--attach", root)
            fields["steps"] = steps
            fields["stabilize_vertex_frames_per_second"] = round(frames * points / steps["stabilize"]["seconds"])
            fields["disk_gb"] = round(sum(p.stat().st_size for p in take.rglob("*") if p.is_file()) / 2**30, 2)
            record(fields)
            if k == 0 and (args.compare or args.compare_only):
                record(chunked_vs_unchunked(root, truth(0, frames), take / "stabilized.usdc"))
            if not args.keep:
                shutil.rmtree(take)


if __name__ == "__main__":
    main()
