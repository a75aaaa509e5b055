"""Build the shipped person-independent removal model (`remove --model default`).

    python -m facedyn.sim.default_model -o facedyn/models/default.removal [--identities N] [--epochs E] [--jobs J] [--data DIR]

Simulates a corpus over several faces (the built-in face with identities and sizes drawn
from --seed: `training_faces`), each take with its own randomly drawn tissue (both
facedyn physics: the spring tissue, and the volumetric one on every --volumetric-every'th
take), under the demo protocol's motions plus running and the procedural dance, turn and
jump, at 60 fps (the rate of most face captures; the model fits takes at its rate only).
Each face's takes are turned into its face frame (facedyn.dynamics.portable), where F
trains on the true skull and the true dynamics with train-removal's recommended inputs:
skull accelerations, sample rest positions, batches of 2,000. The model file records the
exact command, the corpus, the epochs and the seconds taken (`usdfacedyn inspect default`).

Deterministic: the same arguments give the same bytes on one machine (every draw is
seeded, torch runs on --threads threads). The simulator is the training-data source only;
nothing on the production path imports this module.
"""
from __future__ import annotations

import argparse
import shlex
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from facedyn.dynamics.portable import PER_TAKE, face_setup
from facedyn.rig import FaceRig, ShapeOffsets
from facedyn.sim import corpus
from facedyn.sim.default_face import default_face
from facedyn.sim.volumetric import VolumetricParams

FPS = 60.0
SEED = 7000  # identities and takes are drawn from SEED + k: apart from the test set's 2101-2102 and 3101-3103
SIZE_RANGE = (0.85, 1.2)  # a face's overall size, as a factor of the built-in face's
IDENTITY_SCALE = (0.6, 1.6)  # how far from the mean face its identity coefficients reach


def scaled_rig(rig: FaceRig, factor: float, name: str) -> FaceRig:
    """The rig made `factor` times larger (neutral, expression shapes and identity modes)."""
    shapes = tuple(ShapeOffsets(s.indices, (s.offsets * factor).astype(np.float32)) for s in rig.expression_offsets)
    return replace(rig, name=name, neutral=rig.neutral * np.float32(factor), expression_offsets=shapes,
                   identity_modes=rig.identity_modes * np.float32(factor))


def training_faces(count: int, seed: int = SEED) -> list[tuple[FaceRig, dict]]:
    """`count` faces drawn from `seed`: the built-in face's identity modes at a random reach, a random size."""
    base = default_face()
    faces = []
    for k in range(count):
        rng = np.random.default_rng(seed + k)
        reach, size = rng.uniform(*IDENTITY_SCALE), rng.uniform(*SIZE_RANGE)
        name = f"face{k}"
        actor = base.make_actor(seed=seed + k, scale=reach, name=name)
        faces.append((scaled_rig(actor, size, name), {"name": name, "identity_seed": seed + k, "identity_scale": round(reach, 4),
                                                      "size": round(size, 4)}))
    return faces


def face_takes(rig: FaceRig, seed: int, data_dir: Path | None, volumetric_every: int) -> list[corpus.TakeSpec]:
    """One face's takes: the demo protocol plus running and the extra motions, every take its own tissue, at FPS."""
    specs = corpus.protocol(rig, "demo", data_dir, seed=seed, randomize_tissue="take", extra_motions=True, impacts=True)
    runs = [replace(spec, name=spec.name.replace("_walk", "_run"), motion="run", seed=spec.seed + 500,
                    tissue=type(spec.tissue).random(spec.seed + 500)) for spec in specs if spec.motion == "walk"]
    specs = [replace(spec, fps=FPS) for spec in specs + runs]
    if volumetric_every:
        specs = [replace(spec, tissue=VolumetricParams.random(spec.seed)) if k % volumetric_every == volumetric_every - 1 else spec
                 for k, spec in enumerate(specs)]
    return specs


def corpus_takes(faces, args, record: dict):
    """Every face's simulated takes in its face frame, as TrainingSequences, one at a time."""
    from facedyn.dynamics.training_sequence import TrainingSequence

    for k, (rig, description) in enumerate(faces):
        setup, frame = face_setup(rig.topology, rig.neutral, rigid_weights=rig.rigid_weights, face_vertices=rig.face_vertices, uvs=rig.uvs)
        specs = face_takes(rig, args.seed + 100 * (k + 1), args.data, args.volumetric_every)
        done = {spec.name: (take, error) for spec, take, error in corpus.simulate_each(rig, specs, jobs=args.jobs)}
        failed = sum(take is None for take, _ in done.values())
        print(f"{description['name']}: {len(specs) - failed} takes simulated, {failed} failed", file=sys.stderr, flush=True)
        for spec in specs:  # in the specs' order, whatever order the workers finished in
            take, error = done[spec.name]
            if take is None:
                record["failed"].append({"take": f"{description['name']}/{spec.name}", "error": error})
                continue
            record["takes"] += 1
            record["frames"] += len(take.captured)
            record["physics"][take.info["physics"]] = record["physics"].get(take.info["physics"], 0) + 1
            t, q = frame.transforms(take.skull_translate, take.skull_orient)
            yield TrainingSequence(f"{description['name']}/{spec.name}", frame.points(take.captured).astype(np.float32), take.fps, t, q,
                                   "skull", dynamics=(take.offsets @ frame.rotation.T.astype(np.float32)), face=setup)
            del take


def build(args, command: str) -> Path:
    """Simulate, train and write the model; returns its path."""
    import torch

    from facedyn.dynamics.modelfile import save_model
    from facedyn.dynamics.skull_motion import NAMED
    from facedyn.dynamics.training import TrainConfig, train_removal

    torch.set_num_threads(args.threads)
    start = time.perf_counter()
    faces = training_faces(args.identities, args.seed)
    record = {"takes": 0, "frames": 0, "physics": {}, "failed": []}
    config = TrainConfig(epochs=args.epochs, batch_size=2000, subsample=args.subsample, target="truth", skull_motion=NAMED["acceleration"],
                         sample_positions=True, seed=args.seed, device="cpu")

    def report(epoch: int, train_loss: float, val_loss) -> None:
        print(f"epoch {epoch}/{args.epochs}: train {train_loss:.5f} cm^2, validation {val_loss if val_loss is None else round(val_loss, 5)}",
              file=sys.stderr, flush=True)

    with tempfile.TemporaryDirectory(prefix="facedyn-default-") as scratch:
        model = train_removal(corpus_takes(faces, args, record), _first_face(faces), config, report, scratch=scratch)
    model.info["face"] = PER_TAKE
    model.info["training"]["build"] = {
        "command": command, "faces": [d for _, d in faces], "takes": record["takes"], "frames": record["frames"],
        "physics": record["physics"], "failed": record["failed"], "fps": FPS, "epochs": args.epochs, "subsample": args.subsample,
        "seconds": round(time.perf_counter() - start, 1), "threads": args.threads,
        "data": "the built-in face's identities, demo protocol + run, dance, turn, jump" + (", Live Link dialogs" if args.data else ""),
    }
    model.info["training"]["takes"] = len(model.info["training"]["takes"])  # the count: the names are in the build's corpus
    return save_model(model, args.output)


def _first_face(faces):
    """The face setup the model file stores (one of its training faces; each take is set up afresh when applied)."""
    rig = faces[0][0]
    return face_setup(rig.topology, rig.neutral, rigid_weights=rig.rigid_weights, face_vertices=rig.face_vertices, uvs=rig.uvs)[0]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m facedyn.sim.default_model", description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", type=Path, required=True, help="the model file to write (the shipped one: facedyn/models/default.removal)")
    parser.add_argument("--identities", type=int, default=4, help="faces to simulate (default 4)")
    parser.add_argument("--epochs", type=int, default=8, help="training epochs (default 8)")
    parser.add_argument("--subsample", type=float, default=0.5, help="fraction of the (frame, sample) pairs drawn each epoch (default 0.5)")
    parser.add_argument("--jobs", type=int, default=1, help="takes simulated at once (default 1)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads (fixed, so the bytes are the same; default 1)")
    parser.add_argument("--volumetric-every", type=int, default=8, help="every N-th take uses the volumetric physics (0: none; default 8)")
    parser.add_argument("--seed", type=int, default=SEED, help=f"draws faces, tissues and takes (default {SEED})")
    parser.add_argument("--data", type=Path, help="the shared data folder (../shared/data): adds the Live Link dialog takes")
    args = parser.parse_args(argv)
    if args.identities < 1 or args.epochs < 1 or args.jobs < 1 or args.threads < 1 or not 0 < args.subsample <= 1 or args.volumetric_every < 0:
        parser.error("--identities, --epochs, --jobs and --threads must be at least 1, --subsample in (0, 1], --volumetric-every >= 0")
    command = "python -m facedyn.sim.default_model " + " ".join(shlex.quote(a) for a in (argv if argv is not None else sys.argv[1:]))
    path = build(args, command)
    print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
