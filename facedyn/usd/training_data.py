"""Takes for training, from corpus folders or take roots, with the skull they should use.

A stabilized take carries its solved skull (read below any removal attached to it: training
reads the capture, not a quasistatic take). A simulated corpus take also has its true
skull kept apart (facedyn.usd.corpus); training on it (`skull="truth"`) separates the
networks' accuracy from the stabilizer's.
"""
from __future__ import annotations

from pathlib import Path

from pxr import Sdf, Usd

from facedyn.performance import CAPTURED, QUASISTATIC, Performance
from facedyn.usd.corpus import CORPUS_INDEX, read_corpus_index
from facedyn.usd.errors import TakeError
from facedyn.usd.take import TakeSource, read_stage, read_take_below
from facedyn.usd.timing import Timing

SKULL_SOURCES = ("take", "truth")


def take_roots(inputs: list[Path]) -> list[Path]:
    """Expand corpus folders (corpus.json) into their take folders; keep take roots as given."""
    roots = []
    for path in inputs:
        path = Path(path)
        if path.is_dir() and (path / CORPUS_INDEX).is_file():
            roots += [path / take["folder"] for take in read_corpus_index(path)["takes"]]
        elif path.is_dir() and (path / "take.usda").is_file():
            roots.append(path)
        elif path.is_file():
            roots.append(path)
        else:
            raise TakeError(f"{path}: neither a take (.usda/.usdc), a take folder, nor a corpus folder with {CORPUS_INDEX}")
    return roots


def read_training_take(root: Path, skull: str = "take", frames=None) -> tuple[Performance, TakeSource]:
    """A take with its skull solved: the take's own (it must be stabilized) or the simulator's truth."""
    if skull not in SKULL_SOURCES:
        raise ValueError(f"skull must be one of {SKULL_SOURCES}, got {skull!r}")
    folder = root if root.is_dir() else None
    if skull == "truth":
        truth_skull = (folder or root.parent) / "truth" / "skull.usdc"
        capture = (folder or root.parent) / "capture.usdc"
        if not truth_skull.is_file():
            raise TakeError(f"{root}: no truth/skull.usdc beside it (only simulated takes have a true skull)")
        layer = Sdf.Layer.CreateAnonymous(".usda")
        Timing.from_layer(Sdf.Layer.FindOrOpen(str(capture))).apply(layer)  # the in-memory root keeps the take's rate
        layer.subLayerPaths = [str(truth_skull), str(capture)]
        return read_stage(Usd.Stage.Open(layer), truth_skull, frames=frames)
    path = folder / "take.usda" if folder else root
    perf, source = read_take_below(path, QUASISTATIC, frames=frames)  # the stabilized capture, not a removal attached above it
    if perf.skull_orient is None or perf.role == CAPTURED:
        raise TakeError(f"{path}: the take is not stabilized (run `usdfacedyn stabilize` first, or train with --skull truth)")
    return perf, source
