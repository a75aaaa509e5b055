"""`usdfacedyn train-synthesis`: train network H on a corpus and write the model file.

H learns the dynamics offsets x(t) - y(t) of the corpus takes from their skull motion and
the stretch of their quasistatic skin y(t). As in the paper, y(t) comes from a removal
model F run on the takes (`--quasistatic MODEL`); beyond the paper, a simulated corpus can
give its true quasistatic shapes (`--quasistatic truth`). H reads the skull's landmark
accelerations by default, the paper's velocities with `--skull-features velocity`
(facedyn.dynamics.skull_motion says why).
"""
from __future__ import annotations

import time
from pathlib import Path

from facedyn.processors.train_removal import epoch_reporter, load_takes, read_truths, validation_names
from facedyn.progress import Progress


def train_synthesis_command(args) -> dict:
    from facedyn.dynamics.face import FaceSetup
    from facedyn.dynamics.modelfile import load_model, save_model
    from facedyn.dynamics.skull_motion import NAMED
    from facedyn.dynamics.synthesis import synthesis_config, train_synthesis
    from facedyn.dynamics.training import Take
    from facedyn.usd.errors import TakeError

    progress = Progress.silent() if args.json else Progress()
    started = time.perf_counter()
    takes = load_takes(args.inputs, args.skull, args.include, args.exclude, progress)
    first = takes[0][1]
    if first.uvs is None:
        raise TakeError(f"{args.inputs[0]}: the takes have no uvs (primvars:st); stretch features need them")
    if args.quasistatic == "truth":
        truths = read_truths(args.inputs, [name for name, _ in takes])
        quasistatic = {name: truth.points for name, truth in truths.items()}
        face = FaceSetup.from_performance(first, sample_count=args.samples)
    else:
        quasistatic = load_model(args.quasistatic, topology=first.topology, fps=first.fps)
        if quasistatic.kind != "removal":
            raise TakeError(f"{args.quasistatic}: a {quasistatic.kind} model; --quasistatic needs a removal model or 'truth'")
        face = quasistatic.face  # H uses F's samples and landmarks
    config = synthesis_config(epochs=args.epochs, validation=validation_names(args.validation), seed=args.seed, device=args.device,
                              skull_motion=NAMED[args.skull_features])
    read_seconds = time.perf_counter() - started
    on_epoch, last = epoch_reporter(progress, f"train H ({len(takes)} takes)", config.epochs)
    model = train_synthesis([Take.from_performance(perf, name) for name, perf in takes], face, first.uvs,
                            quasistatic, config, on_epoch, backend=args.backend)
    progress.finish()
    model.info["training"].update(skull=args.skull, inputs=[str(p) for p in args.inputs], quasistatic=str(args.quasistatic))
    path = save_model(model, Path(args.output))
    return {
        "model": str(path), "takes": len(takes), "samples": int(len(face.samples)), "fps": model.fps,
        "quasistatic": str(args.quasistatic), "skull_features": model.skull_motion.to_json(), "validation": model.info["validation"], "final_loss": last,
        "seconds": {"read": round(read_seconds, 2), "total": round(time.perf_counter() - started, 2)},
    }
