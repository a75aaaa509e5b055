"""Speed of dynamics synthesis (network H) on an ICT-sized mesh, and of H's training.

Prints one JSON object per case:
- synthesize: the whole of synthesize_dynamics (B(t), stretch S(t), H, propagation, adding
  the offsets to the quasistatic skin) on 1,000 frames of 11,248 points with 344 samples, in frames per second, per
  stretch backend, excluding I/O and the one-off propagation build; beside it, in the
  same run, remove_dynamics on the same take (the reference: the other per-take pass);
- synthesize_stages: the time of each of those steps on the same take (NumPy stretch);
- synthesize_linear_response: synthesize_dynamics with an actor's linear response instead of
  H (the recommended path: no stretch; the skull response in its modal form, its stiffening
  and expression term), fitted on the benchmark's skull motion (bench_remove_speed's);
- train_epoch: one epoch of H's training loop (facedyn.dynamics.training.fit, batches of
  50 frames) on a corpus of ``--corpus-frames`` frames, per corpus size, with one torch
  thread and with torch's default. Only the number of frames and samples matter there,
  so the examples are random arrays of H's shapes.

The mesh is bench_remove_speed's curved sheet (148 x 76 = 11,248 points, the ICT-FaceKit
skin's count) with planar uvs, slowly stretched to stand in for expressions; the models
are randomly initialised: speed does not depend on the weights. Times are the best of
``--repeats`` runs after a warm-up run.

    python benchmarks/bench_synthesize_speed.py [--frames 1000] [--repeats 3] [--corpus-frames 2000 10000] [--torch-threads N] [--out FILE] [--note TEXT]
"""
from __future__ import annotations

import time

import numpy as np
import torch

from bench_remove_speed import FPS, SAMPLES, best_of, emit, linear_response, sheet, take
from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.modelfile import DynamicsModel
from facedyn.dynamics.network import SYNTHESIS_HIDDEN, Network, NetworkSpec, removal_spec
from facedyn.dynamics.removal import remove_dynamics
from facedyn.dynamics.stretch import UVNeighbourhoods, difference_lengths, stretch_features
from facedyn.dynamics.skull_motion import SkullMotionInput
from facedyn.dynamics.synthesis import stretch_arrays, synthesize_dynamics
from facedyn.dynamics.synthesis_training import FrameSet, synthesis_config
from facedyn.dynamics.training import fit
from facedyn.kernels import runtime
from facedyn.performance import UVs
from harness import Recorder, parser


def planar_uvs(points: np.ndarray) -> UVs:
    """Per-vertex uvs from x and y: the sheet is a height field over them."""
    xy = points[:, :2]
    return UVs(((xy - xy.min(axis=0)) / np.ptp(xy, axis=0)).astype(np.float32), None, "vertex")


def expressions(points: np.ndarray, frames: int) -> np.ndarray:
    """(F, N, 3) float32: the sheet stretched up to 5 % sideways and 3 % down, slowly."""
    phase = np.sin(2 * np.pi * 0.5 * np.arange(frames) / FPS)[:, None]
    scale = np.concatenate([1 + 0.05 * phase, 1 - 0.03 * phase, np.ones_like(phase)], axis=1)
    return (points[None] * scale[:, None, :]).astype(np.float32)


def synthesis_model(face: FaceSetup, nb: UVNeighbourhoods) -> DynamicsModel:
    torch.manual_seed(0)
    s = len(face.samples)
    motion = SkullMotionInput()
    network = Network(NetworkSpec(len(face.landmarks) * motion.width * 3 + 2 * s, SYNTHESIS_HIDDEN, 3 * s))
    lengths = difference_lengths(face.rest_points.astype(np.float32), nb)
    return DynamicsModel("synthesis", network, face, FPS, {"stretch_smoothing": 10}, arrays=stretch_arrays(nb, lengths), skull_motion=motion)


def bench_synthesis(args, backends, record: Recorder) -> None:
    points, topology, rigid = sheet()
    face = FaceSetup.build(topology, points, rigid_vertices=rigid, sample_count=SAMPLES)
    nb = UVNeighbourhoods.build(topology, planar_uvs(points), points, face.samples)
    model = synthesis_model(face, nb)
    start = time.perf_counter()
    propagator = model.propagator()
    build_s = time.perf_counter() - start
    quasistatic = expressions(points, args.frames)
    skull_points, translate, orient = take(points, args.frames)  # the skull motion, and a capture under it for the response

    torch.manual_seed(0)
    removal = DynamicsModel("removal", Network(removal_spec()), face, FPS, {"skull": 10, "skin": 10, "target": 10})
    remove_s = best_of(lambda: remove_dynamics(quasistatic, translate, orient, FPS, removal, "numpy"), args.repeats)
    for backend in backends:
        seconds = best_of(lambda: synthesize_dynamics(quasistatic, translate, orient, FPS, model, backend), args.repeats)
        _, offsets = synthesize_dynamics(quasistatic, translate, orient, FPS, model, backend)
        emit(record, {"case": "synthesize", "stretch_backend": backend, "points": len(points), "samples": SAMPLES, "frames": args.frames,
                      "seconds": seconds, "frames_per_s": args.frames / seconds, "target_frames_per_s": 300,
                      "reference_remove_dynamics_frames_per_s": args.frames / remove_s,
                      "one_off_propagation_build_s": build_s, "offset_rms_cm": float(np.sqrt(np.mean(offsets.astype(np.float64) ** 2)))})

    lengths = model.arrays["stretch/neutral_lengths"]
    b = model.skull_motion.features(translate, orient, face.landmarks, FPS)
    s = stretch_features(quasistatic, nb, lengths, "numpy")
    inputs = np.concatenate([b, s.reshape(args.frames, -1)], axis=1)
    d = model.weights.forward(inputs).reshape(args.frames, SAMPLES, 3)  # H in NumPy, as synthesize runs it without a GPU
    network_s = best_of(lambda: model.weights.forward(inputs), args.repeats)
    offsets = np.empty_like(quasistatic)
    stages = {
        "skull_features": best_of(lambda: model.skull_motion.features(translate, orient, face.landmarks, FPS), args.repeats),
        "stretch": best_of(lambda: stretch_features(quasistatic, nb, lengths, "numpy"), args.repeats),
        "network": network_s,
        "propagation": best_of(lambda: propagator.apply_into(d, offsets), args.repeats),
        "add_offsets": best_of(lambda: quasistatic + offsets, args.repeats),
    }
    emit(record, {"case": "synthesize_stages", "stretch_backend": "numpy", "network_device": "numpy", "frames": args.frames, "points": len(points),
                  "seconds": {k: round(v, 5) for k, v in stages.items()}})

    start = time.perf_counter()
    response = linear_response(face, skull_points, translate, orient, template=model)
    fit_s = time.perf_counter() - start
    seconds = best_of(lambda: synthesize_dynamics(quasistatic, translate, orient, FPS, response), args.repeats)
    emit(record, {"case": "synthesize_linear_response", "points": len(points), "samples": SAMPLES, "frames": args.frames, "seconds": seconds,
                  "frames_per_s": args.frames / seconds, "target_frames_per_s": 300, "one_off_fit_s": fit_s})


def bench_training(args, record: Recorder) -> None:
    config = synthesis_config(epochs=1, device="cpu")
    rng = np.random.default_rng(0)
    width = 5 * SkullMotionInput().width * 3 + 2 * SAMPLES  # 5 landmarks
    default_threads = torch.get_num_threads()
    for frames in args.corpus_frames:
        examples = FrameSet(rng.normal(size=(frames, width)).astype(np.float32),
                            rng.normal(0.0, 0.1, (frames, 3 * SAMPLES)).astype(np.float32), torch.device("cpu"))
        for threads in sorted({1, default_threads}):  # batches of 50 are small: one thread may win
            torch.set_num_threads(threads)
            torch.manual_seed(0)
            network = Network(NetworkSpec(width, SYNTHESIS_HIDDEN, 3 * SAMPLES))
            network.set_normalization(np.zeros(width), np.ones(width), np.zeros(3 * SAMPLES), 0.1)
            seconds = best_of(lambda: fit(network, examples, None, config), args.repeats)
            emit(record, {"case": "train_epoch", "corpus_frames": frames, "samples": SAMPLES, "batch_frames": config.batch_size,
                          "steps": -(-frames // config.batch_size), "seconds_per_epoch": seconds,
                          "paper_epochs": 30, "seconds_for_paper_epochs": 30 * seconds})
    torch.set_num_threads(default_threads)


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--frames", type=int, default=1000)
    arguments.add_argument("--repeats", type=int, default=3)
    arguments.add_argument("--corpus-frames", type=int, nargs="+", default=[2000, 10000])
    arguments.add_argument("--torch-threads", type=int, default=None, help="torch's CPU threads (default: torch's choice)")
    args = arguments.parse_args()
    if args.torch_threads:
        torch.set_num_threads(args.torch_threads)
    backends = ["numpy"] + (["opencl"] if runtime.available() else [])
    with Recorder("bench_synthesize_speed", args) as record:
        bench_synthesis(args, backends, record)
        bench_training(args, record)


if __name__ == "__main__":
    main()
