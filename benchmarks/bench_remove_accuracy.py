"""Removal accuracy against truth, the paper's Fig. 5 protocol (issue: remove).

For each held-out platform frequency: train F on the other five frequencies plus walk,
run and hop (neutral + held expressions, 3 s each at 120 fps, 0.01 cm tracking noise),
then remove the dynamics of the held-out takes and of a dialog take (Live Link speech)
under CMU 131_01 walking that no training take resembles. F is trained twice per split:
on the paper's moving-average targets (w = 10) and on the simulator's true dynamics
(``--targets``), each with the paper's skull input (landmark velocities) or, with
``--skull-features velocity acceleration``, also with facedyn's (landmark accelerations over
t-30..t+10, facedyn.dynamics.skull_motion). F on true dynamics also learns from
``--performances`` Live Link performances other than the test's speech, each under every
training motion: a performance has a true quasistatic shape in simulation but no
moving-average target, so the paper's F learns from held expressions only. Prints one
JSON object per case, every figure an RMS over the face vertices (after propagation to the
whole mesh) as a fraction of the true dynamics' RMS:

- removed: the removed offsets against the true dynamics, i.e. the removed take against
  the true quasistatic skin plus the capture's own tracking noise, which removing dynamics
  does not (and should not) touch; beside it "do nothing" (100%) and the moving average
  applied directly (the paper's training target used as the answer);
- removed_vs_true_quasistatic: the removed take against the noise-free true quasistatic
  skin, with the tracking noise's share of it (noise_floor) alongside.

    python benchmarks/bench_remove_accuracy.py --rig ../shared/data/ict-facekit/ict_face_rig.usdc [--held 6 7 8 9 10 11] [--skull-features velocity acceleration] [--performances 4] [--out FILE] [--note TEXT]
"""
from __future__ import annotations

import itertools
import os
import time
from pathlib import Path

import numpy as np
import torch

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.removal import remove_dynamics
from facedyn.dynamics.skull_motion import NAMED as SKULL_INPUTS
from facedyn.dynamics.targets import dynamic_offsets
from facedyn.dynamics.training import TARGETS, TrainConfig, train_removal
from facedyn.dynamics.training_sequence import TrainingSequence
from facedyn.processors.corpus_writer import load_rig
from facedyn.evaluation import residual_fraction
from facedyn.sim.corpus import PERFORMANCES, PLATFORM_HZ, SPEECH, TakeSpec, held_expressions, simulate_takes
from harness import Recorder, parser
from spill import scratch_folder, spill

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
NOISE_CM = 0.01
MOTIONS = ["walk", "run", "hop"] + [f"platform:{hz}" for hz in PLATFORM_HZ]


def corpus_specs(rig, expressions: int, seconds: float, performances: int) -> list[TakeSpec]:
    specs = []
    for i, expression in enumerate([None] + held_expressions(rig, expressions)):
        for motion in MOTIONS:
            specs.append(TakeSpec(f"{expression or 'neutral'}_{motion}", motion, expression, duration_s=seconds,
                                  seed=i * 31 + len(specs), noise_cm=NOISE_CM))
    if DATA.is_dir():
        for k, csv in enumerate(PERFORMANCES[:performances]):
            for motion in MOTIONS:
                specs.append(TakeSpec(f"performance_{Path(csv).stem}_{motion}", motion, dialog=str(DATA / "livelink-face" / csv),
                                      duration_s=seconds, seed=7000 + 97 * k + len(specs), noise_cm=NOISE_CM))
        specs.append(TakeSpec("dialog_cmu_walk", f"bvh:{DATA / 'cmu-mocap' / '131_01.bvh'}",
                              dialog=str(DATA / "livelink-face" / SPEECH),
                              duration_s=5.0, seed=4242, noise_cm=NOISE_CM))
    return specs


class Kept:
    """What the benchmark keeps of a simulated take: the capture and its true dynamics
    (memory-mapped from `store`: a corpus with performances outgrows 24 GiB of memory), and
    for test takes the tracking noise on the face vertices."""

    def __init__(self, take, face_vertices, test: bool, store: Path):
        self.name = take.spec.name
        self.fps = take.fps
        self.translate, self.orient = take.skull_translate, take.skull_orient
        self.captured = spill(store / f"{self.name}.captured.npy", take.captured)
        self.dynamics = spill(store / f"{self.name}.dynamics.npy", take.offsets)
        fv = face_vertices
        self.noise = (take.captured[:, fv] - take.quasistatic[:, fv] - take.offsets[:, fv]) if test else None

    def as_take(self) -> TrainingSequence:
        return TrainingSequence(self.name, self.captured, self.fps, self.translate, self.orient, "skull", self.dynamics)


def evaluate(model, group: list[Kept], face_vertices) -> dict:
    """Offset errors of F and of the moving average, and the noise-inclusive residual."""
    fv = face_vertices
    removed, average, truth, noise = [], [], [], []
    for t in group:
        _, offsets = remove_dynamics(t.captured, t.translate, t.orient, t.fps, model)
        removed.append(offsets[:, fv])
        average.append(dynamic_offsets(t.captured[:, fv], space="skull").astype(np.float32))
        truth.append(t.dynamics[:, fv])
        noise.append(t.noise)
    removed, average, truth, noise = (np.concatenate(a) for a in (removed, average, truth, noise))
    zero = np.zeros_like(truth)
    # removed take - true quasistatic = (dynamics + noise) - removed offsets
    with_noise = residual_fraction(truth + noise - removed, zero, truth)
    return {
        "removed": round(residual_fraction(removed, truth, truth)["fraction"], 3),
        "moving_average": round(residual_fraction(average, truth, truth)["fraction"], 3),
        "do_nothing": round(residual_fraction(zero, truth, truth)["fraction"], 3),
        "removed_vs_true_quasistatic": round(with_noise["fraction"], 3),
        "noise_floor": round(residual_fraction(noise, zero, truth)["fraction"], 3),
        "residual_cm": round(residual_fraction(removed, truth, truth)["residual_rms_cm"], 4),
        "dynamics_rms_cm": round(with_noise["dynamics_rms_cm"], 4),
    }


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--rig", type=Path)
    arguments.add_argument("--expressions", type=int, default=10)
    arguments.add_argument("--seconds", type=float, default=3.0)
    arguments.add_argument("--epochs", type=int, default=40)
    arguments.add_argument("--subsample", type=float, default=0.25)
    arguments.add_argument("--held", type=int, nargs="*", default=list(PLATFORM_HZ), help="held-out frequencies to evaluate")
    arguments.add_argument("--targets", nargs="*", choices=TARGETS, default=list(TARGETS))
    arguments.add_argument("--device", default="cpu", help="torch device for training (the targets are set for 2 CPU cores)")
    arguments.add_argument("--skull-features", nargs="+", choices=tuple(SKULL_INPUTS), default=["velocity"],
                           help="F's skull inputs to compare: the paper's velocities (default) and/or facedyn's accelerations")
    arguments.add_argument("--performances", type=int, default=4, choices=range(len(PERFORMANCES) + 1), metavar=f"0..{len(PERFORMANCES)}",
                           help="Live Link performances (not the test's) captured under every training motion, for truth targets (default 4, the speech takes: the measured configuration)")
    args = arguments.parse_args()
    with Recorder("bench_remove_accuracy", args) as record:
        measure(args, record)


def measure(args, record: Recorder) -> None:
    """Simulate the corpus, then train and evaluate F for each held-out frequency, target and skull input."""
    torch.set_num_threads(os.cpu_count() or 1)
    rig = load_rig(args.rig)  # the built-in face without --rig
    face = FaceSetup.build(rig.topology, rig.neutral, rigid_weights=rig.rigid_weights, face_vertices=rig.face_vertices)
    fv = rig.face_vertices
    started = time.perf_counter()
    specs = corpus_specs(rig, args.expressions, args.seconds, args.performances)
    store = scratch_folder()
    takes = {t.spec.name: Kept(t, fv, t.spec.motion.startswith(("platform", "bvh")), store)
             for t in simulate_takes(rig, specs, jobs=os.cpu_count() or 1)}
    record({"case": "corpus", "rig": rig.name, "takes": len(takes), "frames": sum(len(t.captured) for t in takes.values()),
            "seconds": round(time.perf_counter() - started, 1)})
    dialog = [t for t in takes.values() if t.name.startswith("dialog")]
    for held in args.held:
        trainable = [t for t in takes.values() if not t.name.startswith("dialog") and not t.name.endswith(f"platform:{held}")]
        tests = {f"held-out {held} Hz": [t for t in takes.values() if t.name.endswith(f"platform:{held}") and not t.name.startswith("performance")]}
        if dialog:
            tests["dialog under CMU 131_01 walking (never trained on)"] = dialog
        for target, skull_features in itertools.product(args.targets, args.skull_features):
            train = [t.as_take() for t in trainable if target == "truth" or not t.name.startswith("performance")]
            config = TrainConfig(epochs=args.epochs, subsample=args.subsample, validation=(train[-1].name,), target=target, device=args.device,
                                 skull_motion=SKULL_INPUTS[skull_features])
            t0 = time.perf_counter()
            model = train_removal(train, face, config)
            seconds = time.perf_counter() - t0
            curve = model.info["loss_curve"][-1]
            for label, group in tests.items():
                result = {"case": "removal accuracy", "rig": rig.name, "target": target, "skull_features": skull_features, "test": label, "held_out_hz": held,
                          "train_takes": len(train), "train_performance_takes": sum(t.name.startswith("performance") for t in train),
                          "train_pairs": model.info["training"]["train_pairs"],
                          "epochs": args.epochs, "subsample": args.subsample, "train_seconds": round(seconds, 1),
                          "final_train_loss_cm2": float(f"{curve['train_loss']:.4g}"), "final_val_loss_cm2": float(f"{curve['val_loss']:.4g}"),
                          **evaluate(model, group, fv)}
                record(result)


if __name__ == "__main__":
    main()
