"""Simulated takes on disk: the take a processor sees, and its truth kept apart.

Each take is a folder:

    <take>/capture.usdc            the tracked mesh in world space (what a studio would have)
    <take>/take.usda               root: subLayers = [capture.usdc]
    <take>/truth/skull.usdc        over: the true skull transforms, skin in skull space
    <take>/truth/quasistatic.usdc  over: the true jiggle-free skin y(t) and offsets u(t)
    <take>/truth.usda              root: [truth/quasistatic, truth/skull, capture]

so a processor reading take.usda never sees the truth by accident, and an evaluation opens
truth.usda. A corpus folder lists its takes in corpus.json.
"""
from __future__ import annotations

import json
import os
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

import facedyn
from facedyn.progress import Progress
from facedyn.sim.corpus import SimulatedPerformance, TakeSpec, simulate_takes
from facedyn.sim.rig import FaceRig
from facedyn.sim.tissue import TissueParams
from facedyn.usd import schema
from facedyn.usd.errors import TakeError
from facedyn.usd.layers import LayerContent, write_layer, write_take_root
from facedyn.usd.runs import LAYER, LayerInput, content_id
from facedyn.usd.take import read_take
from facedyn.usd.timing import Timing

CORPUS_INDEX = "corpus.json"


def write_simulated_take(folder: Path, take: SimulatedPerformance, rig: FaceRig) -> dict:
    """Write one simulated take (capture + truth layers + roots) into `folder`."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "truth").mkdir(exist_ok=True)
    frames = take.frames
    timing = Timing(take.fps, take.fps, float(frames[0]), float(frames[-1]))
    spec = {k: v for k, v in asdict(take.spec).items() if v is not None}
    face = schema.FaceAttributes(
        role="captured", rest_points=rig.neutral, rigid_weights=rig.rigid_weights, face_vertices=rig.face_vertices,
        alignment_vertices=alignment_vertices(rig),
    )
    capture = write_layer(
        folder / "capture.usdc",
        LayerContent(frames=frames, points=take.world_points(), topology=rig.topology, uvs=rig.uvs, face=face,
                     skull=schema.SkullAttributes(solver="identity")),
        timing, _provenance("simulate", spec, frames, [rig.name]), define=True,
    )
    skull = write_layer(
        folder / "truth" / "skull.usdc",
        LayerContent(frames=frames, points=take.captured, skull_translate=take.skull_translate, skull_orient=take.skull_orient,
                     face=schema.FaceAttributes(role="stabilized"), skull=schema.SkullAttributes(solver="truth")),
        timing, _provenance("simulate-truth-skull", spec, frames, _layers(capture)),
    )
    quasistatic = write_layer(
        folder / "truth" / "quasistatic.usdc",
        LayerContent(frames=frames, points=take.quasistatic, offsets=take.offsets, face=schema.FaceAttributes(role="quasistatic")),
        timing, _provenance("simulate-truth-quasistatic", spec, frames, _layers(skull, capture)),
    )
    write_take_root(folder / "take.usda", [capture], timing)
    write_take_root(folder / "truth.usda", [quasistatic, skull, capture], timing)
    magnitude = np.linalg.norm(take.offsets, axis=-1)
    face_magnitude = magnitude[:, rig.face_vertices]
    return {
        "name": take.spec.name,
        "folder": folder.name,
        "frames": int(len(frames)),
        "fps": take.fps,
        "spec": spec,
        "peak_offset_mm": round(float(magnitude.max()) * 10, 3),
        "rms_offset_mm": round(float(np.sqrt(np.mean(face_magnitude**2))) * 10, 3),
    }


def alignment_vertices(rig: FaceRig) -> np.ndarray | None:
    """The rig's outer eye corners and under-nose vertex, when it names them."""
    names = ("eye_corner_left", "eye_corner_right", "nose_base")
    if not all(name in rig.landmarks for name in names):
        return None
    return np.array([rig.landmarks[name] for name in names], np.int32)


def _layers(*paths: Path) -> list[LayerInput]:
    """The truth layers below a truth layer, as the inputs it is computed from (so truth.usda's stack reads as current)."""
    return [LayerInput(str(Path(p).resolve()), content_id(p), LAYER) for p in paths]


def _provenance(processor: str, spec: dict, frames: np.ndarray, inputs: list) -> schema.Provenance:
    return schema.Provenance(processor, f"facedyn {facedyn.__version__}", spec, (float(frames[0]), float(frames[-1])), inputs)


def build_corpus(
    output: Path,
    rig: FaceRig,
    specs: list[TakeSpec],
    tissue: TissueParams | None = None,
    progress: Progress | None = None,
    description: dict | None = None,
    jobs: int = 1,
) -> dict:
    """Simulate (`jobs` takes at a time) and write every take of `specs`; return the corpus index."""
    progress = progress or Progress.silent()
    output = corpus_folder(output)
    started = time.perf_counter()
    written = 0.0
    takes = []
    progress.start(f"simulate {len(specs)} takes", len(specs))
    for take in simulate_takes(rig, specs, tissue, jobs):
        t0 = time.perf_counter()
        takes.append(write_simulated_take(output / take.spec.name, take, rig))
        written += time.perf_counter() - t0
        progress.advance()
    progress.finish()
    return write_corpus_index(output, rig, tissue, takes, description, jobs, written, time.perf_counter() - started)


def corpus_folder(output: Path) -> Path:
    """The corpus folder, created if needed; a clear error when it cannot be written."""
    output = Path(output)
    output.mkdir(parents=True, exist_ok=True)
    if not os.access(output, os.W_OK):
        raise TakeError(f"{output}: corpus folder is not writable")
    return output


def write_corpus_index(output: Path, rig: FaceRig, tissue: TissueParams | None, takes: list[dict], description: dict | None,
                       jobs: int, written: float, total: float) -> dict:
    """Write corpus.json for the written takes (write_simulated_take's entries, in order); return it."""
    frames = sum(t["frames"] for t in takes)
    index = {
        "rig": rig.name,
        "points": rig.point_count,
        "tissue": asdict(tissue or TissueParams()),
        "takes": takes,
        "description": description or {},
        "frames": frames,
        "jobs": jobs,
        "seconds": {"write": round(written, 2), "total": round(total, 2)},
        "simulated_frames_per_second": round(frames / total, 1),  # corpus built per wall-clock second, writing included
    }
    (output / CORPUS_INDEX).write_text(json.dumps(index, indent=2))
    return index


def read_corpus_index(folder: Path) -> dict:
    path = Path(folder) / CORPUS_INDEX
    if not path.is_file():
        raise TakeError(f"{folder}: not a facedyn corpus (no {CORPUS_INDEX}; build one with `usdfacedyn synth`)")
    return json.loads(path.read_text())


def read_truth(take_folder: Path, frames: tuple[float, float] | None = None):
    """A take's truth as a Performance: true skull transforms, points = y(t), offsets = u(t)."""
    truth, _ = read_take(Path(take_folder) / "truth.usda", frames=frames)
    return truth
