"""Takes for training, from corpus folders or take roots, with the skull they should use.

A stabilized take carries its solved skull (read below any removal attached to it: training
reads the capture, not a quasistatic take). A simulated corpus take also has its true
skull kept apart (facedyn.usd.corpus_files); training on it (`skull="truth"`) separates the
networks' accuracy from the stabilizer's.
"""
from __future__ import annotations

from pathlib import Path

from pxr import Sdf, Usd

from facedyn.performance import CAPTURED, QUASISTATIC, TAKE_ROOT_FILE, Performance, role
from facedyn.usd.corpus_files import CORPUS_INDEX, read_corpus_index
from facedyn.usd.errors import TakeError
from facedyn.usd.take import TakeSource, find_face_mesh, read_stage, select_time_codes, stage_below
from facedyn.usd.timing import Timing

SKULL_SOURCES = ("take", "truth")


def take_roots(inputs: list[Path]) -> list[Path]:
    """Expand corpus folders (corpus.json) into their take folders; keep take roots as given."""
    roots = []
    for path in inputs:
        path = Path(path)
        if path.is_dir() and (path / CORPUS_INDEX).is_file():
            roots += [path / take["folder"] for take in read_corpus_index(path)["takes"]]
        elif path.is_dir() and (path / TAKE_ROOT_FILE).is_file():
            roots.append(path)
        elif path.is_file():
            roots.append(path)
        else:
            raise TakeError(f"{path}: neither a take (.usda/.usdc), a take folder, nor a corpus folder with {CORPUS_INDEX}")
    return roots


def read_training_take(root: Path, skull: str = "take", frames=None) -> tuple[Performance, TakeSource]:
    """A take with its skull solved: the take's own (it must be stabilized) or the simulator's truth."""
    stage, path = _training_stage(root, skull)
    perf, source = read_stage(stage, path, frames=frames)
    _check_stabilized(path, perf, skull)
    return perf, source


def read_training_head(root: Path, skull: str = "take") -> tuple[Performance, int]:
    """(the take's first frame as read_training_take reads it, its frame count): what a trainer
    checks and sets up from before it reads each take's frames in turn."""
    stage, path = _training_stage(root, skull)
    time_codes = select_time_codes(stage, find_face_mesh(stage), None)
    first = float(time_codes[0])
    head, _ = read_stage(stage, path, frames=(first, first))
    _check_stabilized(path, head, skull)
    return head, len(time_codes)


def _training_stage(root: Path, skull: str) -> tuple[Usd.Stage, Path]:
    """(the stage a trainer reads the take from, the path that names it): the take below its
    removal, or the capture under the simulator's true skull."""
    if skull not in SKULL_SOURCES:
        raise ValueError(f"skull must be one of {SKULL_SOURCES}, got {skull!r}")
    folder = root if root.is_dir() else None
    if skull == "truth":
        truth_skull = (folder or root.parent) / "truth" / "skull.usdc"
        capture = (folder or root.parent) / role(CAPTURED).layer_file()
        if not truth_skull.is_file():
            raise TakeError(f"{root}: no truth/skull.usdc beside it (only simulated takes have a true skull)")
        layer = Sdf.Layer.CreateAnonymous(".usda")
        Timing.from_layer(Sdf.Layer.FindOrOpen(str(capture))).apply(layer)  # the in-memory root keeps the take's rate
        layer.subLayerPaths = [str(truth_skull), str(capture)]
        return Usd.Stage.Open(layer), truth_skull
    path = folder / TAKE_ROOT_FILE if folder else root
    return stage_below(path, QUASISTATIC), path  # the stabilized capture, not a removal attached above it


def _check_stabilized(path: Path, perf: Performance, skull: str) -> None:
    if skull == "take" and (perf.skull_orient is None or perf.role == CAPTURED):
        raise TakeError(f"{path}: the take is not stabilized (run `usdfacedyn stabilize` first, or train with --skull truth)")
