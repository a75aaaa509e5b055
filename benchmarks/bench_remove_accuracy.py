"""Removal accuracy against truth, the paper's Fig. 5 protocol (issue: remove).

For each held-out platform frequency: train F on the other five frequencies plus walk,
run and hop (held expressions), then remove the dynamics of the held-out takes and of a
dialog take under CMU walking that was never trained on. Prints one JSON object per case:
residual RMS of removed vs true quasistatic over the face as a fraction of the true
dynamics' RMS, beside "do nothing" (100%) and the moving average applied directly.

    python benchmarks/bench_remove_accuracy.py [--rig ICT.usdc] [--expressions 10] [--epochs 40] [--held 9]
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.removal import remove_dynamics
from facedyn.dynamics.skull import to_skull
from facedyn.dynamics.targets import quasistatic_targets
from facedyn.dynamics.training import Take, TrainConfig, train_removal
from facedyn.evaluation import residual_fraction
from facedyn.sim.corpus import PLATFORM_HZ, TakeSpec, held_expressions, simulate_take
from facedyn.sim.default_face import default_face

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
NOISE_CM = 0.01


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rig", type=Path)
    parser.add_argument("--expressions", type=int, default=10)
    parser.add_argument("--seconds", type=float, default=3.0)
    parser.add_argument("--epochs", type=int, default=40)
    parser.add_argument("--subsample", type=float, default=0.25)
    parser.add_argument("--held", type=int, nargs="*", default=list(PLATFORM_HZ), help="held-out frequencies to evaluate")
    args = parser.parse_args()
    torch.set_num_threads(2)
    if args.rig:
        from facedyn.usd.rig import read_blendshape_rig

        rig = read_blendshape_rig(args.rig)
    else:
        rig = default_face()
    expressions = [None] + held_expressions(rig, args.expressions)
    face_setup = FaceSetup.build(rig.topology, rig.neutral, rigid_weights=rig.rigid_weights, face_vertices=rig.face_vertices)
    started = time.perf_counter()
    takes = {}
    for i, expression in enumerate(expressions):
        for motion in ["walk", "run", "hop"] + [f"platform:{hz}" for hz in PLATFORM_HZ]:
            spec = TakeSpec(f"{expression or 'neutral'}_{motion}", motion, expression, duration_s=args.seconds, seed=i * 31 + len(takes), noise_cm=NOISE_CM)
            takes[spec.name] = simulate_take(rig, spec)
    dialog = None
    if DATA.is_dir():
        spec = TakeSpec("dialog_cmu_walk", f"bvh:{DATA / 'cmu-mocap' / '131_01.bvh'}", dialog=str(DATA / "livelink-face" / "MySlate_3_Jason_Millers_iPhone.csv"),
                        duration_s=5.0, seed=4242, noise_cm=NOISE_CM)
        dialog = simulate_take(rig, spec)
    print(json.dumps({"case": "corpus", "rig": rig.name, "takes": len(takes), "seconds": round(time.perf_counter() - started, 1)}), flush=True)
    for held in args.held:
        train = [Take(name, t.captured, t.fps, t.skull_translate, t.skull_orient) for name, t in takes.items() if not name.endswith(f"platform:{held}")]
        t0 = time.perf_counter()
        model = train_removal(train, face_setup, TrainConfig(epochs=args.epochs, subsample=args.subsample, validation=(train[-1].name,)))
        train_seconds = time.perf_counter() - t0
        tests = {f"held-out {held} Hz": [t for n, t in takes.items() if n.endswith(f"platform:{held}")]}
        if dialog is not None:
            tests["dialog under CMU walking (never trained on)"] = [dialog]
        for label, group in tests.items():
            removed, truth, offsets, average, captured = [], [], [], [], []
            for t in group:
                q, _ = remove_dynamics(t.captured, t.skull_translate, t.skull_orient, t.fps, model)
                removed.append(q)
                truth.append(t.quasistatic)
                offsets.append(t.offsets)
                captured.append(t.captured)
                world = t.world_points()
                y = quasistatic_targets(world, t.skull_translate, t.skull_orient)
                average.append(to_skull(y, t.skull_translate, t.skull_orient))
            cat = lambda arrays: np.concatenate(arrays)  # noqa: E731
            f = rig.face_vertices
            result = {
                "case": "removal accuracy", "rig": rig.name, "test": label, "held_out_hz": held, "train_takes": len(train),
                "epochs": args.epochs, "train_seconds": round(train_seconds, 1),
                "removed": round(residual_fraction(cat(removed), cat(truth), cat(offsets), f)["fraction"], 3),
                "moving_average": round(residual_fraction(cat(average), cat(truth), cat(offsets), f)["fraction"], 3),
                "do_nothing": round(residual_fraction(cat(captured), cat(truth), cat(offsets), f)["fraction"], 3),
                "dynamics_rms_cm": round(residual_fraction(cat(captured), cat(truth), cat(offsets), f)["dynamics_rms_cm"], 4),
            }
            print(json.dumps(result), flush=True)


if __name__ == "__main__":
    main()
