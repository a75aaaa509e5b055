"""`usdfacedyn train-removal`: train network F on a corpus and write the model file.

Not a layer processor: its output is a model (weights + JSON metadata, facedyn.dynamics
.modelfile), the input of the remove processor.
"""
from __future__ import annotations

import fnmatch
import time
from dataclasses import replace
from pathlib import Path

from facedyn.errors import UsageError
from facedyn.progress import Progress


def load_takes(inputs: list[Path], skull: str, include: str | None, exclude: str | None, progress: Progress):
    """(name, Performance) of every selected take, all of one topology."""
    from facedyn.usd.errors import TakeError
    from facedyn.usd.training_data import read_training_take, take_roots

    roots = take_roots(inputs)
    named = [(_take_name(root), root) for root in roots]
    if include:
        named = [(n, r) for n, r in named if fnmatch.fnmatch(n, include)]
    if exclude:
        named = [(n, r) for n, r in named if not fnmatch.fnmatch(n, exclude)]
    if not named:
        raise UsageError("no take left to train on after --include/--exclude")
    takes = []
    progress.start("read takes", len(named))
    for name, root in named:
        perf, _ = read_training_take(root, skull)
        if takes and perf.topology.fingerprint() != takes[0][1].topology.fingerprint():
            raise TakeError(f"{root}: its mesh topology differs from {takes[0][0]}'s; a model is trained for one topology")
        takes.append((name, perf))
        progress.advance()
    progress.finish()
    return takes


def validation_names(text: str | None) -> tuple[str, ...] | None:
    """--validation a,b -> ("a", "b"); None or empty -> None (the trainer's default)."""
    return tuple(name for name in (text or "").split(",") if name) or None


def epoch_reporter(progress: Progress, task: str, epochs: int):
    """(a training callback that advances `progress` per epoch, the dict holding the last losses)."""
    last: dict = {}
    progress.start(task, epochs)

    def on_epoch(epoch, train_loss, val_loss):
        last.update(epoch=epoch, train=train_loss, val=val_loss)
        progress.advance()

    return on_epoch, last


def read_truths(inputs: list[Path], names: list[str]) -> dict:
    """{take name: its truth Performance (points = true quasistatic, offsets = true dynamics)}
    for simulated corpus takes (facedyn.usd.corpus keeps the truth beside each take)."""
    from facedyn.usd.corpus import read_truth
    from facedyn.usd.training_data import take_roots

    folders = {_take_name(root): root if root.is_dir() else root.parent for root in take_roots(inputs)}
    return {name: read_truth(folders[name]) for name in names}


def _take_name(root: Path) -> str:
    return root.name if root.is_dir() else root.parent.name if root.name in ("take.usda", "truth.usda") else root.stem


def train_removal_command(args) -> dict:
    """Run the training the parsed command line asks for; return a JSON-able report."""
    from facedyn.dynamics.face import FaceSetup
    from facedyn.dynamics.modelfile import save_model
    from facedyn.dynamics.skull_motion import SkullMotionInput
    from facedyn.dynamics.training import Take, TrainConfig, train_removal

    if args.target == "truth" and args.skull != "truth":
        raise UsageError("--target truth needs --skull truth: the true dynamics are vectors in the true skull's frame, "
                         "which a solved skull matches only up to an unknown rigid transform")
    progress = Progress.silent() if args.json else Progress()
    started = time.perf_counter()
    takes = load_takes(args.inputs, args.skull, args.include, args.exclude, progress)
    face = FaceSetup.from_performance(takes[0][1], sample_count=args.samples)
    config = TrainConfig(epochs=args.epochs, subsample=args.subsample, validation=validation_names(args.validation),
                         seed=args.seed, device=args.device, target=args.target,
                         skull_motion=SkullMotionInput() if args.skull_features == "acceleration" else None)
    training = [Take.from_performance(perf, name) for name, perf in takes]
    if args.target == "truth":
        truths = read_truths(args.inputs, [name for name, _ in takes])
        training = [replace(take, dynamics=truths[take.name].offsets) for take in training]
    read_seconds = time.perf_counter() - started
    on_epoch, curve_tail = epoch_reporter(progress, f"train F ({len(takes)} takes)", config.epochs)
    model = train_removal(training, face, config, on_epoch, backend=args.backend)
    progress.finish()
    model.info["training"]["skull"] = args.skull
    model.info["training"]["inputs"] = [str(p) for p in args.inputs]
    path = save_model(model, args.output)
    return {
        "model": str(path),
        "takes": len(takes),
        "samples": int(len(face.samples)),
        "fps": model.fps,
        "skull_features": model.skull_input.to_json(),
        "validation": model.info["validation"],
        "final_loss": curve_tail,
        "seconds": {"read": round(read_seconds, 2), "total": round(time.perf_counter() - started, 2)},
    }
