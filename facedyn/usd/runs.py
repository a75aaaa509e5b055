"""Run identities: what a layer was computed from, in a form a later reader can check.

Every facedyn layer records a `run` id, a short sha256 of its processor, version,
parameters, frame range and the ids of its inputs. Every input is identified by its
content: a sha256 of the bytes a reader of it reads (a layer written as value clips: its
file and its clips), so an edit of any value below a layer (a point moved, a model
retrained) changes the id, and a take folder that is moved or copied keeps its ids, as
nothing in them depends on where the files lie. A reader can tell, without recomputing
anything, whether what a layer was computed from is still what lies below it.

Layers written before inputs were identified by content (`INPUT_IDENTITY` absent) recorded,
for an input facedyn layer, the `run` that layer records; `legacy_id` gives that id, so
such takes are still checked, by runs as before.
"""
from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path

from pxr import Sdf, Tf

from facedyn.io import digests
from facedyn.io.files import sha256_of_file
from facedyn.usd.clips import CLIPS_SUFFIX, clips_folder, glob_escape

ID_LENGTH = 16  # hex digits kept of a sha256: 64 bits, ample to tell runs of one take apart
IN_MEMORY = "(in memory)"  # what an input that is no file (an anonymous layer) is recorded as
INPUT_IDENTITY = "content"  # customLayerData["facedyn"]["inputIdentity"]: the input ids are content ids
LAYER, FILE = "layer", "file"  # input kinds: a layer of the take's stack, any other file (a model, a source)


@dataclass(frozen=True)
class LayerInput:
    """One thing a run read: a file path (or a label such as a rig name), its content id, its kind.

    `run` is "" for a label that names no file: nothing a reader could check. `kind` is LAYER
    for a layer of the stack the run read (it must stay below the result), FILE otherwise.
    """

    path: str
    run: str
    kind: str = FILE

    @classmethod
    def of(cls, value: "str | os.PathLike | LayerInput") -> "LayerInput":
        """An input from a path, identified now (or a LayerInput identified when it was read)."""
        if isinstance(value, LayerInput):
            return value
        text = str(value)
        if text.startswith("anon:"):
            return cls(IN_MEMORY, "")
        path = Path(text)
        return cls(str(path.resolve()), content_id(path)) if path.is_file() else cls(text, "")


def read_elsewhere(inputs) -> list[LayerInput]:
    """Layers a run read from another take (retarget's --source, a take given as skull motion), as
    inputs of kind FILE: their content is checked like a model's, but they are no layers of the
    stack the result is placed in, so their absence from it says nothing."""
    return [LayerInput(i.path, i.run) for i in inputs if i.run]


def content_id(path: str | os.PathLike) -> str:
    """A short sha256 of the file at path as a reader reads it: its bytes, and its value clips' ("" if missing)."""
    path = Path(path)
    if not path.is_file():
        return ""
    own = _file_digest(path)
    clips = _clip_files(path)
    if not clips:
        return own
    parts = [own] + [f"{clip.name}:{_file_digest(clip)}" for clip in clips]
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:ID_LENGTH]


def _clip_files(path: Path) -> list[Path]:
    """The clip layers a layer written as value clips reads (facedyn.usd.clips: a folder named after its run)."""
    if not any(path.parent.glob(f"{glob_escape(path.stem)}.*{CLIPS_SUFFIX}")):
        return []  # the common case, decided without opening the layer
    run = _recorded_run(path)
    folder = clips_folder(path, run) if run else None
    return sorted(p for p in folder.iterdir() if p.is_file()) if folder and folder.is_dir() else []


def legacy_id(path: str | os.PathLike) -> str:
    """An input's id as layers written before content ids recorded it: a facedyn layer's run, else its bytes' digest."""
    path = Path(path)
    if not path.is_file():
        return ""
    return _recorded_run(path) or _file_digest(path)


def _recorded_run(path: Path) -> str:
    """The `run` in a USD layer's customLayerData["facedyn"] ("" when it is no facedyn layer)."""
    if not Sdf.FileFormat.FindByExtension(path.suffix.lstrip(".")):
        return ""
    data = facedyn_metadata(path)
    return str(data.get("run", "")) if data else ""


def facedyn_metadata(path: str | os.PathLike) -> dict | None:
    """customLayerData["facedyn"] of the layer file at path, read fresh from disk (metadata only)."""
    try:
        layer = Sdf.Layer.OpenAsAnonymous(str(path), metadataOnly=True)
    except Tf.ErrorException:
        return None
    if layer is None:
        return None
    data = dict(layer.customLayerData).get("facedyn")
    return dict(data) if isinstance(data, dict) else None


_DIGESTS: dict[tuple, str] = {}
BLOCK = 1 << 22  # bytes hashed at a time: the file is streamed, never whole in memory


def _file_digest(path: str | os.PathLike) -> str:
    """A short sha256 of a file's bytes, streamed.

    Remembered for the life of the process per file identity and change time (inode, size,
    mtime and ctime, which no tool sets back), so a step that reads a layer and then checks
    its stack hashes it once, and kept on disk for later commands (facedyn.io.digests).
    """
    path = Path(path).resolve()
    stat = path.stat()
    key = (str(path), stat.st_dev, stat.st_ino, stat.st_size, stat.st_mtime_ns, stat.st_ctime_ns)
    if key not in _DIGESTS:
        _DIGESTS[key] = digests.digest(path, lambda file: sha256_of_file(file, BLOCK)[:ID_LENGTH])
    return _DIGESTS[key]


def run_id(processor: str, version: str, parameters_json: str, frame_range: tuple[float, float], input_runs: list[str]) -> str:
    """The deterministic id of a run: a short sha256 of its canonical JSON description."""
    canonical = json.dumps(
        {
            "processor": processor,
            "version": version,
            "parameters": json.loads(parameters_json),
            "frameRange": [float(f) for f in frame_range],
            "inputs": list(input_runs),
        },
        sort_keys=True,
        separators=(",", ":"),
    )
    return hashlib.sha256(canonical.encode()).hexdigest()[:ID_LENGTH]
