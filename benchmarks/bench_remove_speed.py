"""Speed of dynamics removal on an ICT-sized mesh, each step beside its reference.

Prints one JSON object per case:
- features: B(t) and X_i(t) for 1,000 frames x 344 samples, NumPy vs the OpenCL kernel;
- laplacian: the batched sparse Laplacian on 11,248 points x 1,000 frames, SciPy vs OpenCL;
- auto: the backend ``--backend auto`` picks for each kernel, beside the faster of the two
  measured here;
- removal: the whole of remove_dynamics (features, network F, propagation, subtraction) on
  1,000 frames, in frames per second, excluding I/O and the one-off propagation build;
- removal_with_io: the remove processor as `usdfacedyn remove` runs it (read the stabilized
  take and the model file, remove, write the quasistatic layer), ICT rig only;
- removal_linear_response: the same take removed by an actor's linear response (the skull
  response in its modal form, its stiffening and expression term), alone and as `remove
  --blend` runs it (the mean of F's removal and the response's), excluding the one-off fit.

The mesh is the ICT-FaceKit skin (11,248 points, ../shared/data) with its rigid region, or
where the rig is absent a synthetic curved sheet of 148 x 76 = 11,248 points with a rigid
top band. F is randomly initialised: speed does not depend on the weights; the linear response
is fitted on the benchmark's take itself (its two halves as a session, its ridge chosen there).
Times are the best of ``--repeats`` runs after a warm-up run.

    python benchmarks/bench_remove_speed.py [--frames 1000] [--repeats 3] [--torch-threads N] [--rig PATH|sheet] [--out FILE] [--note TEXT]
"""
from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from facedyn.dynamics.bands import BandWeights
from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.features import compute_features
from facedyn.dynamics.modelfile import DynamicsModel
from facedyn.dynamics.network import SYNTHESIS_HIDDEN, Network, NetworkSpec, removal_spec
from facedyn.dynamics.propagate import laplacian_apply
from facedyn.dynamics.removal import remove_dynamics
from facedyn.dynamics.response import fit_linear_response, remove_with_response
from facedyn.dynamics.skull import to_world
from facedyn.dynamics.skull_motion import SkullMotionInput
from facedyn.geometry import quaternion
from facedyn.kernels import runtime
from facedyn.performance import Topology

from harness import Recorder, parser

ROWS, COLS, FPS, SAMPLES = 148, 76, 120.0, 344
ICT_RIG = Path(__file__).resolve().parents[2] / "shared" / "data" / "ict-facekit" / "ict_face_rig.usdc"


def sheet(rows: int = ROWS, cols: int = COLS, rigid_rows: int = 12) -> tuple[np.ndarray, Topology, np.ndarray]:
    """(points, topology, rigid vertices) of a 20 x 16 cm sheet bent like a face, its top `rigid_rows` rigid."""
    ys, xs = np.mgrid[0:rows, 0:cols].astype(np.float64)
    angle = (xs / (cols - 1) - 0.5) * 1.6
    points = np.stack([10 * np.sin(angle), (ys / (rows - 1) - 0.5) * 20, 10 * np.cos(angle) + 0.3 * np.sin(ys / 3)], -1).reshape(-1, 3)
    a = (np.arange(rows - 1)[:, None] * cols + np.arange(cols - 1)[None, :]).ravel()
    tris = np.concatenate([np.stack([a, a + 1, a + cols + 1], 1), np.stack([a, a + cols + 1, a + cols], 1)])
    rigid = np.arange((rows - rigid_rows) * cols, rows * cols)
    return points, Topology(np.full(len(tris), 3, np.int32), tris.ravel().astype(np.int32)), rigid


def take(points: np.ndarray, frames: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(skull-space points float32, translate, orient): a bobbing head with jiggling skin."""
    time_s = np.arange(frames) / FPS
    translate = np.stack([0.5 * np.sin(time_s), 150 + 0.3 * np.sin(2 * np.pi * 8 * time_s), 0.2 * time_s], 1)
    orient = quaternion.from_rotvec(np.stack([0.05 * np.sin(2 * np.pi * 8 * time_s), 0.1 * np.sin(time_s), 0 * time_s], 1))
    jiggle = 0.2 * np.sin(2 * np.pi * 8 * time_s + 1.0)[:, None, None] * np.array([0.0, 1.0, 0.3])
    return (points[None] + jiggle).astype(np.float32), translate, orient


def mesh(rig_arg: str):
    """(rig or None, points, topology, face setup): the ICT rig when there is one, else the sheet."""
    path = Path(rig_arg) if rig_arg != "sheet" else None
    if path is not None and path.is_file():
        from facedyn.usd.blendshape_rig import read_blendshape_rig

        rig = read_blendshape_rig(path)
        face = FaceSetup.build(rig.topology, rig.neutral, rigid_weights=rig.rigid_weights, face_vertices=rig.face_vertices, sample_count=SAMPLES)
        return rig, rig.neutral.astype(np.float64), rig.topology, face
    points, topology, rigid = sheet()
    return None, points, topology, FaceSetup.build(topology, points, rigid_vertices=rigid, sample_count=SAMPLES)


def write_still_take(folder: Path, rig, skull_points, translate, orient, root_name: str) -> Path:
    """A stabilized take of `skull_points` under the skull (translate, orient), no dynamics,
    written as the simulator writes one, with its root `root_name` listing skull and capture."""
    from facedyn.sim.corpus import SimulatedPerformance, TakeSpec
    from facedyn.usd.corpus_files import write_simulated_take
    from facedyn.usd.layers import write_take_root
    from facedyn.usd.timing import Timing

    frames = len(skull_points)
    zeros = np.zeros_like(skull_points)
    take = SimulatedPerformance(TakeSpec("speed", "still"), np.arange(1, frames + 1, dtype=np.float64), FPS, translate, orient,
                                skull_points, zeros, zeros, np.zeros((frames, rig.expression_count), np.float32))
    write_simulated_take(folder, take, rig)
    return write_take_root(folder / root_name, [folder / "truth" / "skull.usdc", folder / "capture.usdc"], Timing(FPS, FPS, 1.0, float(frames)))


def removal_with_io(rig, skull_points, translate, orient, model, repeats: int) -> dict:
    """Time the remove processor end to end on a stabilized take written to a scratch folder."""
    from facedyn.dynamics.modelfile import save_model
    from facedyn.processors import registry
    from facedyn.processors.base import Request
    from facedyn.processors.runner import execute
    from facedyn.progress import Progress

    frames = len(skull_points)
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch) / "take"
        root = write_still_take(folder, rig, skull_points, translate, orient, "stabilized.usda")
        model_path = save_model(model, Path(scratch) / "actor.removal")
        output = folder / "quasistatic.usdc"
        processor = registry.load("remove")
        seconds = best_of(lambda: execute(processor, Request([root], output, params={"model": str(model_path)}), Progress.silent()), repeats)
        return {"seconds": seconds, "frames_per_s": frames / seconds, "layer_mb": round(output.stat().st_size / 2**20, 1)}


def linear_response(face: FaceSetup, skull_points: np.ndarray, translate: np.ndarray, orient: np.ndarray, template=None):
    """An actor's linear response fitted on the take's two halves as its session, its ridge
    chosen there as `train-synthesis --response linear` chooses it; template: a synthesis
    model of the face (None: a bare one: a response reads only its face and skull input)."""
    if template is None:
        motion = SkullMotionInput()
        spec = NetworkSpec(len(face.landmarks) * motion.width * 3 + 2 * len(face.samples), SYNTHESIS_HIDDEN, 3 * len(face.samples))
        template = DynamicsModel("synthesis", Network(spec), face, FPS, {"stretch_smoothing": 10}, skull_motion=motion)
    half = len(skull_points) // 2
    takes = [dict(name=f"half{k}", points=skull_points[part], fps=FPS, translate=translate[part], orient=orient[part], space="skull")
             for k, part in enumerate((slice(0, half), slice(half, None)))]
    return fit_linear_response(template, takes)


def best_of(fn, repeats: int) -> float:
    fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return min(times)


def emit(record: Recorder, fields: dict) -> None:
    """Record fields with the cores, torch threads and OpenCL device they were measured with."""
    fields.update(cpu_count=os.cpu_count(), torch_threads=torch.get_num_threads())
    if runtime.available():
        fields["device"] = runtime.describe()
    record(fields)


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--frames", type=int, default=1000)
    arguments.add_argument("--repeats", type=int, default=3)
    arguments.add_argument("--torch-threads", type=int, default=None, help="torch's CPU threads (default: torch's choice)")
    arguments.add_argument("--rig", default=str(ICT_RIG), help="a blend-shape rig's mesh (default: ICT-FaceKit), or 'sheet'")
    args = arguments.parse_args()
    with Recorder("bench_remove_speed", args) as record:
        measure(args, record)


def measure(args, record: Recorder) -> None:
    """Each kernel per backend, what auto picks, the whole removal, the linear response and (ICT rig) the processor."""
    if args.torch_threads:
        torch.set_num_threads(args.torch_threads)
    backends = ["numpy"] + (["opencl"] if runtime.available() else [])

    start = time.perf_counter()
    rig, points, topology, face = mesh(args.rig)
    setup_s = time.perf_counter() - start
    torch.manual_seed(0)
    model = DynamicsModel("removal", Network(removal_spec()), face, FPS, {"skull": 10, "skin": 10, "target": 10})
    start = time.perf_counter()
    propagator = model.propagator()
    build_s = time.perf_counter() - start
    skull_points, translate, orient = take(points, args.frames)

    mesh_name = rig.name if rig is not None else "sheet"
    world_samples = to_world(skull_points[:, face.samples], translate, orient).astype(np.float32)
    ref = compute_features(world_samples, translate, orient, face.landmarks, FPS, space="world", backend="numpy")
    measured = {}
    for backend in backends:
        seconds = best_of(lambda: compute_features(world_samples, translate, orient, face.landmarks, FPS, space="world", backend=backend), args.repeats)
        out = compute_features(world_samples, translate, orient, face.landmarks, FPS, space="world", backend=backend)
        diff = max(np.abs(out.skin - ref.skin).max() / np.abs(ref.skin).max(), np.abs(out.skull - ref.skull).max() / np.abs(ref.skull).max())
        measured.setdefault("features", {})[backend] = seconds
        emit(record, {"case": "features", "backend": backend, "frames": args.frames, "samples": SAMPLES, "seconds": seconds,
                      "frames_per_s": args.frames / seconds, "max_rel_diff_vs_numpy": float(diff)})

    u = propagator.apply(np.random.default_rng(0).normal(0, 0.2, (args.frames, SAMPLES, 3)))
    ref = laplacian_apply(propagator.laplacian, u, "numpy")
    for backend in backends:
        seconds = best_of(lambda: laplacian_apply(propagator.laplacian, u, backend), args.repeats)
        diff = np.abs(laplacian_apply(propagator.laplacian, u, backend) - ref).max() / np.abs(ref).max()
        measured.setdefault("laplacian", {})[backend] = seconds
        emit(record, {"case": "laplacian", "backend": backend, "mesh": mesh_name, "points": len(points), "frames": args.frames, "seconds": seconds,
                      "frames_per_s": args.frames / seconds, "max_rel_diff_vs_numpy": float(diff)})

    # what --backend auto picks (it measures once per process, then remembers)
    compute_features(world_samples, translate, orient, face.landmarks, FPS, space="world", backend="auto")
    laplacian_apply(propagator.laplacian, u, "auto")
    for kernel, times in measured.items():
        emit(record, {"case": "auto", "kernel": kernel, "chosen": runtime.choose_backend("auto", kernel),
                      "faster_here": min(times, key=times.get), "seconds": times})

    for backend in backends:
        seconds = best_of(lambda: remove_dynamics(skull_points, translate, orient, FPS, model, backend), args.repeats)
        _, offsets = remove_dynamics(skull_points, translate, orient, FPS, model, backend)
        residual = propagator.residual(offsets, "numpy")
        emit(record, {"case": "removal", "features_backend": backend, "mesh": mesh_name, "points": len(points), "samples": SAMPLES, "frames": args.frames,
                      "seconds": seconds, "frames_per_s": args.frames / seconds, "target_frames_per_s": 300,
                      "one_off_setup_s": {"rig_samples_and_landmarks": setup_s, "propagation_matrix": build_s},
                      "smoothness_residual_median": float(np.median(residual))})

    start = time.perf_counter()
    response = linear_response(face, skull_points, translate, orient)
    fit_s = time.perf_counter() - start
    alone = best_of(lambda: remove_with_response(skull_points, translate, orient, FPS, response), args.repeats)
    blended = best_of(lambda: BandWeights.mean(2).combine([remove_dynamics(skull_points, translate, orient, FPS, model, "auto"),
                                                           remove_with_response(skull_points, translate, orient, FPS, response)],
                                                          FPS), args.repeats)
    emit(record, {"case": "removal_linear_response", "mesh": mesh_name, "points": len(points), "samples": SAMPLES, "frames": args.frames,
                  "seconds": alone, "frames_per_s": args.frames / alone, "blend_with_f_seconds": blended, "blend_with_f_frames_per_s": args.frames / blended,
                  "target_frames_per_s": 300, "one_off_fit_s": fit_s, "temporal_kernels": response.info["calibration"]["temporal_kernels"]})
    if rig is not None:
        emit(record, {"case": "removal_with_io", "mesh": mesh_name, "frames": args.frames, **removal_with_io(rig, skull_points, translate, orient, model, args.repeats)})


if __name__ == "__main__":
    main()
