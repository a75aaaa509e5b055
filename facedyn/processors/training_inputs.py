"""What the trainers share: reading takes from corpora, their truth, their common flags, their checks and reports."""
from __future__ import annotations

import fnmatch
from pathlib import Path

from facedyn.errors import UsageError
from facedyn.performance import TAKE_ROOT_FILE
from facedyn.processors.base import Parameter, check_device
from facedyn.progress import Progress

TRAINING_PARAMETERS = (
    Parameter("skull", str, "take", "the takes' solved skull, or a simulated corpus's true skull", ("take", "truth")),
    Parameter("samples", int, 344, "skin samples when the takes (or the removal model) define none", minimum=1, maximum=100000),
    Parameter("validation", str, "", "comma-separated take names held out for validation (default: the last take)", metavar="NAMES"),
    Parameter("include", str, "", "only takes whose name matches one of these comma-separated glob patterns", metavar="PATTERNS"),
    Parameter("exclude", str, "", "leave out takes whose name matches one of these comma-separated glob patterns", metavar="PATTERNS"),
    Parameter("seed", int, 0, "seed of the network's initialization and the epochs' sampling", minimum=0, maximum=2**32 - 1),
    Parameter("device", str, "auto", "torch device: auto, cpu, cuda, cuda:N", check=check_device),
    Parameter("actor", Path, None, "the actor asset whose skin samples, landmarks and rigid region the model uses (default: "
              "the one the takes' roots record, else the first take's own)", metavar="ACTOR"),
)


def _matches(name: str, patterns: str) -> bool:
    """Whether a take name matches any of the comma-separated glob patterns."""
    return any(fnmatch.fnmatch(name, pattern.strip()) for pattern in patterns.split(",") if pattern.strip())


def select_takes(inputs: list[Path], params: dict) -> list[tuple[str, Path]]:
    """(name, root) of every take --include/--exclude select, validation names checked."""
    from facedyn.usd.training_data import take_roots

    named = [(take_name(root), root) for root in take_roots(inputs)]
    if params["include"]:
        named = [(n, r) for n, r in named if _matches(n, params["include"])]
    if params["exclude"]:
        named = [(n, r) for n, r in named if not _matches(n, params["exclude"])]
    if not named:
        raise UsageError("no take left to train on after --include/--exclude")
    missing = [name for name in validation_names(params) or () if name not in {n for n, _ in named}]
    if missing:
        raise UsageError(f"--validation: no take named {', '.join(missing)} among the {len(named)} selected takes")
    return named


def load_takes(inputs: list[Path], params: dict, progress: Progress) -> list:
    """(name, Performance) of every selected take, all of one topology; validation names checked."""
    from facedyn.usd.training_data import read_training_take

    named = select_takes(inputs, params)
    takes = []
    progress.start("read takes", len(named))
    for name, root in named:
        perf, _ = read_training_take(root, params["skull"])
        check_topology(takes, name, perf, root)
        takes.append((name, perf))
        progress.advance()
    progress.finish()
    training_skull_frame(takes)
    return takes


def take_heads(named: list[tuple[str, Path]], skull: str) -> list[tuple[str, object, int]]:
    """(name, the take's first frame, its frame count) of each take, all of one topology and
    skull frame: what a trainer checks and sets up from before it reads any take whole."""
    from facedyn.usd.training_data import read_training_head

    heads = []
    for name, root in named:
        head, frames = read_training_head(root, skull)
        check_topology(heads, name, head, root)
        heads.append((name, head, frames))
    training_skull_frame([(name, head) for name, head, _ in heads])
    return heads


def training_sequences(named: list[tuple[str, Path]], skull: str, truth: bool):
    """Each take as a TrainingSequence, read when the trainer asks for it (with its true
    dynamics from the corpus when `truth`): a trainer holds one take's frames at a time."""
    from dataclasses import replace

    from facedyn.dynamics.training_sequence import TrainingSequence
    from facedyn.usd.corpus_files import read_truth
    from facedyn.usd.training_data import read_training_take

    for name, root in named:
        perf, _ = read_training_take(root, skull)
        sequence = TrainingSequence.from_performance(perf, name)
        if truth:
            sequence = replace(sequence, dynamics=read_truth(root if root.is_dir() else root.parent).offsets)
        yield sequence


def check_topology(takes: list, name: str, perf, root: Path) -> None:
    """A model is trained for one topology: refuse a take whose mesh differs from the first's."""
    from facedyn.usd.errors import TakeError

    if takes and perf.topology.fingerprint() != takes[0][1].topology.fingerprint():
        raise TakeError(f"{root}: its mesh topology differs from {takes[0][0]}'s; a model is trained for one topology")


def training_skull_frame(takes: list) -> str | None:
    """The one skull frame every training take is in (None for takes without a rest mesh).

    A network trained across takes in different skull frames learns their disagreement as
    dynamics, so mixed frames are refused.
    """
    from facedyn.usd.errors import TakeError

    frames = {name: take_skull_frame(perf) for name, perf in takes}
    distinct = sorted(set(frames.values()), key=str)
    if len(distinct) > 1:
        by_frame = {frame: [n for n, f in frames.items() if f == frame] for frame in distinct}
        listing = "; ".join(f"{', '.join(names[:3])}{'...' if len(names) > 3 else ''}" for names in by_frame.values())
        raise TakeError(f"the training takes are in {len(distinct)} different skull frames ({listing}); stabilize every take "
                        "of the actor with --actor ACTOR so they share one")
    return distinct[0]


def training_face(inputs: list[Path], params: dict, takes: list):
    """(the face setup the model is trained with, what the model records about its frame).

    The actor's (--actor, or the one the takes' roots record) when there is one: its skin
    samples, landmarks and rigid region, with every take checked to be in its skull frame,
    so a model does not depend on which take is listed first. Else the first take's own.
    """
    from facedyn.dynamics.face import FaceSetup
    from facedyn.usd.actor_asset import read_actor_for
    from facedyn.usd.errors import TakeError

    frame = training_skull_frame(takes)
    path = params["actor"] or recorded_training_actor(inputs)
    if path is None:
        return FaceSetup.from_performance(takes[0][1], sample_count=params["samples"]), {"skull_frame": frame}
    actor = read_actor_for(path, takes[0][1].topology, takes[0][0])
    if frame != actor.skull_frame:
        raise TakeError(f"{path}: the training takes are not in the actor {actor.name}'s skull frame; stabilize every take "
                        f"with --actor {path} (or import it with --actor) first")
    face = FaceSetup.build(actor.topology, actor.neutral, rigid_weights=actor.rigid_weights, face_vertices=actor.face_vertices,
                           samples=actor.skin_samples, landmarks=actor.landmarks, sample_count=params["samples"], uvs=actor.uvs)
    return face, {"skull_frame": frame, "actor": actor.name}


def recorded_training_actor(inputs: list[Path]) -> Path | None:
    """The one actor the training takes' roots record (import --actor), or None; two actors are an error."""
    from facedyn.usd.errors import TakeError
    from facedyn.usd.rootedit import recorded_actor
    from facedyn.usd.training_data import take_roots

    found = {}
    for root in take_roots(inputs):
        actor = recorded_actor(root / TAKE_ROOT_FILE if root.is_dir() else root)
        if actor is not None:
            found.setdefault(actor, take_name(root))
    if len(found) > 1:
        listing = ", ".join(f"{name}: {path}" for path, name in found.items())
        raise TakeError(f"the training takes record {len(found)} different actors ({listing}); a model is trained for one actor")
    return next(iter(found), None)


def take_skull_frame(perf) -> str | None:
    from facedyn.performance import skull_frame_id

    return skull_frame_id(perf.rest_points, perf.topology) if perf.rest_points is not None else None


def validation_names(params: dict) -> tuple[str, ...] | None:
    """--validation a,b -> ("a", "b"); empty -> None (the trainer's default)."""
    return tuple(name for name in params["validation"].split(",") if name) or None


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
    for simulated corpus takes (facedyn.usd.corpus_files keeps the truth beside each take)."""
    from facedyn.usd.corpus_files import read_truth
    from facedyn.usd.training_data import take_roots

    folders = {take_name(root): root if root.is_dir() else root.parent for root in take_roots(inputs)}
    return {name: read_truth(folders[name]) for name in names}


def take_name(root: Path) -> str:
    return root.name if root.is_dir() else root.parent.name if root.name in (TAKE_ROOT_FILE, "truth.usda") else root.stem


def training_summary(model, takes, face, last: dict) -> dict:
    """What a trainer reports: the data, the validation errors, the last losses."""
    return {"takes": len(takes), "samples": int(len(face.samples)), "fps": model.fps,
            "skull_features": model.skull_input.to_json(), "validation": model.info["validation"], "final_loss": last}


def check_session_lengths(takes: list, model, settle_s: float) -> None:
    """Every session take keeps enough frames after --settle for the response to count it."""
    from facedyn.dynamics.response import MIN_ROWS, settled_frames
    from facedyn.usd.errors import TakeError

    for name, perf in takes:
        keep = settled_frames(perf.frame_count, perf.fps, settle_s, model)
        if keep.stop - keep.start < MIN_ROWS:
            raise TakeError(f"take {name!r}: {perf.frame_count} frames leave {max(keep.stop - keep.start, 0)} after "
                            f"--settle {settle_s:g} s and the skull window's last {model.skull_input.future + 1}; a linear response "
                            f"needs {MIN_ROWS} per take")
