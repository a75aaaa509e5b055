"""Simulated takes on disk: the take a processor sees, and its truth kept apart.

Each take is a folder:

    <take>/capture.usdc            the tracked mesh in world space (what a studio would have)
    <take>/take.usda               root: subLayers = [capture.usdc]
    <take>/truth/skull.usdc        over: the true skull transforms, skin in skull space
    <take>/truth/quasistatic.usdc  over: the true jiggle-free skin y(t) and offsets u(t)
    <take>/truth.usda              root: [truth/quasistatic, truth/skull, capture]

so a processor reading take.usda never sees the truth by accident, and an evaluation opens
truth.usda. A corpus folder lists its takes in corpus.json (`takes`), and the takes the
simulator could not integrate with their errors (`failed`, which no reader trains on).

A corpus is built to survive interruptions: each take is written under a temporary name and
renamed into place with its recipe (`<take>/simulated.json`: a hash of its TakeSpec, the
rig and the tissue), so a folder with a recipe is complete, and a later run on the same
folder keeps the takes whose recipe matches and simulates only the rest.

This module is the corpus's files and imports no simulator, so the trainers and `evaluate`
read a corpus without loading the physics; `facedyn.processors.corpus_writer` simulates the
takes and writes them with it.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
from dataclasses import asdict
from pathlib import Path

import numpy as np

import facedyn
from facedyn.errors import FacedynError
from facedyn.performance import CAPTURED, QUASISTATIC, STABILIZED, TAKE_ROOT_FILE, role
from facedyn.rig import FaceRig, alignment_vertices
from facedyn.usd import schema
from facedyn.usd.errors import TakeError
from facedyn.usd.layers import LayerContent, write_layer, write_take_root
from facedyn.usd.runs import LAYER, LayerInput, content_id
from facedyn.usd.take import read_take
from facedyn.usd.timing import Timing

CORPUS_INDEX = "corpus.json"
TAKE_RECIPE = "simulated.json"  # in a complete take folder: its recipe and its corpus.json entry
PARTIAL = ".partial-"  # a take folder being written: .<take>.partial-<pid>


def write_simulated_take(folder: Path, take, rig: FaceRig) -> dict:
    """Write one simulated take (a facedyn.sim.corpus.SimulatedPerformance: capture + truth layers + roots) into `folder`."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "truth").mkdir(exist_ok=True)
    frames = take.frames
    timing = Timing(take.fps, take.fps, float(frames[0]), float(frames[-1]))
    spec = {k: v for k, v in asdict(take.spec).items() if v is not None}
    face = schema.FaceAttributes(
        role=CAPTURED, rest_points=rig.neutral, rigid_weights=rig.rigid_weights, face_vertices=rig.face_vertices,
        alignment_vertices=alignment_vertices(rig),
    )
    capture = write_layer(
        folder / role(CAPTURED).layer_file(),
        LayerContent(frames=frames, points=take.world_points(), topology=rig.topology, uvs=rig.uvs, face=face,
                     skull=schema.SkullAttributes(solver="identity")),
        timing, _provenance("simulate", spec, frames, [rig.name]), define=True,
    )
    skull = write_layer(
        folder / "truth" / "skull.usdc",
        LayerContent(frames=frames, points=take.captured, skull_translate=take.skull_translate, skull_orient=take.skull_orient,
                     face=schema.FaceAttributes(role=STABILIZED), skull=schema.SkullAttributes(solver="truth")),
        timing, _provenance("simulate-truth-skull", spec, frames, _layers(capture)),
    )
    quasistatic = write_layer(
        folder / "truth" / "quasistatic.usdc",
        LayerContent(frames=frames, points=take.quasistatic, offsets=take.offsets, face=schema.FaceAttributes(role=QUASISTATIC)),
        timing, _provenance("simulate-truth-quasistatic", spec, frames, _layers(skull, capture)),
    )
    write_take_root(folder / TAKE_ROOT_FILE, [capture], timing)
    write_take_root(folder / "truth.usda", [quasistatic, skull, capture], timing)
    magnitude = np.linalg.norm(take.offsets, axis=-1)
    face_magnitude = magnitude[:, rig.face_vertices]
    return {
        "name": take.spec.name,
        "folder": folder.name,
        "frames": int(len(frames)),
        "fps": take.fps,
        "spec": spec,
        "substeps": int(take.info.get("substeps", 1)),  # steps per frame the physics took (more where it had to retry)
        "peak_offset_mm": round(float(magnitude.max()) * 10, 3),
        "rms_offset_mm": round(float(np.sqrt(np.mean(face_magnitude**2))) * 10, 3),
    }


def _layers(*paths: Path) -> list[LayerInput]:
    """The truth layers below a truth layer, as the inputs it is computed from (so truth.usda's stack reads as current)."""
    return [LayerInput(str(Path(p).resolve()), content_id(p), LAYER) for p in paths]


def _provenance(processor: str, spec: dict, frames: np.ndarray, inputs: list) -> schema.Provenance:
    return schema.Provenance(processor, f"facedyn {facedyn.__version__}", spec, (float(frames[0]), float(frames[-1])), inputs)


def rig_fingerprint(rig: FaceRig) -> str:
    """A hash of everything of the rig a simulation reads: neutral, topology, shapes, rigid weights."""
    digest = hashlib.sha256()
    for array in (rig.neutral, rig.topology.face_vertex_counts, rig.topology.face_vertex_indices, rig.rigid_weights):
        digest.update(np.ascontiguousarray(array).tobytes())
    for name, (indices, offsets) in zip(rig.expression_names, rig.expression_offsets):
        digest.update(name.encode())
        digest.update(np.ascontiguousarray(indices).tobytes())
        digest.update(np.ascontiguousarray(offsets).tobytes())
    return digest.hexdigest()


def take_recipe(spec, rig_hash: str, tissue) -> dict:
    """What decides a take's content, JSON-able: its spec (a facedyn.sim.corpus.TakeSpec; a data file by its name and content,
    not by the path it was given as), the rig's fingerprint and the corpus's tissue, with their hash."""
    recipe = {k: v for k, v in asdict(spec).items() if v is not None}
    if spec.dialog is not None:
        recipe["dialog"] = _file_key(spec.dialog)
    kind, _, arg = spec.motion.partition(":")
    if kind == "bvh":
        path, sep, joint = arg.partition("#")
        recipe["motion"] = f"bvh:{_file_key(path)}{sep}{joint}"
    recipe = {"spec": recipe, "rig": rig_hash, "tissue": asdict(tissue) if tissue is not None else None}
    recipe["hash"] = hashlib.sha256(json.dumps(recipe, sort_keys=True, default=str).encode()).hexdigest()
    return recipe


def _file_key(path: str) -> str:
    """A data file as `name@sha256` (the same curves given by another path are the same recipe)."""
    try:
        return f"{Path(path).resolve().name}@{hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]}"
    except OSError:
        return path  # unreadable: the simulation will say so


def complete_take(folder: Path, recipe: dict, refuse: bool = True) -> dict | None:
    """The corpus entry of a complete take of this recipe in `folder`; None when there is none to keep.

    A take folder of another recipe is a FacedynError naming what differs (`refuse`: not
    overwritten) or None (simulated again); so is a folder without a recipe (an older
    facedyn's take, simulated again).
    """
    marker = folder / TAKE_RECIPE
    if not marker.is_file():
        return None
    try:
        kept = json.loads(marker.read_text())
        ok = kept["recipe"]["hash"] == recipe["hash"]
        entry = kept["entry"]
    except (OSError, ValueError, KeyError, TypeError):
        raise FacedynError(f"{marker}: unreadable; delete {folder} to simulate the take again") from None
    if not ok and not refuse:
        return None
    if not ok:
        differs = _differences(kept["recipe"], recipe)
        raise FacedynError(f"{folder}: a take simulated with another recipe (it differs in {differs or 'the simulator'}); write the corpus "
                           f"to another folder, or delete {folder} to simulate it again")
    return entry


def _differences(old: dict, new: dict) -> str:
    names = [f"spec.{k}" for k in sorted(set(old.get("spec", {})) | set(new["spec"])) if old.get("spec", {}).get(k) != new["spec"].get(k)]
    names += [k for k in ("rig", "tissue") if old.get(k) != new[k]]
    return ", ".join(names)


def write_take_atomically(output: Path, take, rig: FaceRig, recipe: dict) -> dict:
    """Write a take under a temporary name with its recipe and rename it into place; return its corpus entry."""
    name = take.spec.name
    partial = output / f".{name}{PARTIAL}{os.getpid()}"
    if partial.exists():
        shutil.rmtree(partial)
    try:
        entry = write_simulated_take(partial, take, rig)
        entry["folder"] = name
        (partial / TAKE_RECIPE).write_text(json.dumps({"recipe": recipe, "entry": entry}, indent=2, default=str))
        final = output / name
        if final.exists():  # a take of another recipe, or an older facedyn's (complete_take kept neither): replaced
            shutil.rmtree(final)
        partial.rename(final)
    except BaseException:
        shutil.rmtree(partial, ignore_errors=True)
        raise
    return entry


def sweep_partial_takes(output: Path) -> None:
    """Remove take folders (and corpus.json) left half-written by runs that died (their pid is gone)."""
    for path in output.glob(f".*{PARTIAL}*"):
        pid = path.name.rpartition(PARTIAL)[2]
        if pid.isdigit() and not _alive(int(pid)):
            if path.is_dir() and not path.is_symlink():
                shutil.rmtree(path, ignore_errors=True)
            else:
                path.unlink(missing_ok=True)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def corpus_folder(output: Path) -> Path:
    """The corpus folder, created if needed; a clear error when it cannot be written."""
    output = Path(output)
    output.mkdir(parents=True, exist_ok=True)
    if not os.access(output, os.W_OK):
        raise TakeError(f"{output}: corpus folder is not writable")
    return output


def write_corpus_index(output: Path, rig: FaceRig, tissue: dict, takes: list[dict], description: dict | None,
                       jobs: int, written: float, total: float, *, failed: list[dict] = (), resumed: int = 0) -> dict:
    """Write corpus.json (atomically) for the written takes (write_simulated_take's entries, in order) and the failed
    ones ({name, error}; `resumed`: takes kept from an earlier run; `tissue`: the tissue's parameters); return it."""
    frames = sum(t["frames"] for t in takes)
    index = {
        "rig": rig.name,
        "points": rig.point_count,
        "tissue": tissue,
        "takes": takes,
        "failed": list(failed),
        "resumed": resumed,
        "description": description or {},
        "frames": frames,
        "jobs": jobs,
        "seconds": {"write": round(written, 2), "total": round(total, 2)},
        "simulated_frames_per_second": round(frames / total, 1),  # corpus built per wall-clock second, writing included
    }
    partial = output / f".{CORPUS_INDEX}{PARTIAL}{os.getpid()}"
    partial.write_text(json.dumps(index, indent=2))
    partial.replace(output / CORPUS_INDEX)
    return index


def read_corpus_index(folder: Path) -> dict:
    path = Path(folder) / CORPUS_INDEX
    if not path.is_file():
        raise TakeError(f"{folder}: not a facedyn corpus (no {CORPUS_INDEX}; build one with `usdfacedyn simulate`)")
    return json.loads(path.read_text())


def read_truth(take_folder: Path, frames: tuple[float, float] | None = None):
    """A take's truth as a Performance: true skull transforms, points = y(t), offsets = u(t)."""
    truth, _ = read_take(Path(take_folder) / "truth.usda", frames=frames)
    return truth
