"""Run identities: what a layer was computed from, in a form a later reader can check.

Every facedyn layer records a `run` id, a short sha256 of its processor, version,
parameters, frame range and the run ids of its inputs. An input that is a facedyn layer is
identified by its own recorded run, any other file (a model, a source mesh) by a sha256 of
its bytes. So a reader can tell, without recomputing anything, whether what a layer was
computed from is still what lies below it: the ids differ as soon as anything upstream does.
"""
from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path

from pxr import Sdf, Tf

ID_LENGTH = 16  # hex digits kept of a sha256: 64 bits, ample to tell runs of one take apart
IN_MEMORY = "(in memory)"  # what an input that is no file (an anonymous layer) is recorded as


@dataclass(frozen=True)
class LayerInput:
    """One thing a run read: a file path (or a label such as a rig name) and its run id.

    `run` is "" for a label that names no file: nothing a reader could check.
    """

    path: str
    run: str

    @classmethod
    def of(cls, value: "str | os.PathLike | LayerInput") -> "LayerInput":
        """An input from a path, identified now (or a LayerInput identified when it was read)."""
        if isinstance(value, LayerInput):
            return value
        text = str(value)
        if text.startswith("anon:"):
            return cls(IN_MEMORY, "")
        path = Path(text)
        return cls(str(path.resolve()), current_run(path)) if path.is_file() else cls(text, "")


def current_run(path: str | os.PathLike) -> str:
    """The run recorded in a facedyn layer at path, else a digest of the file's bytes ("" if missing)."""
    path = Path(path)
    if not path.is_file():
        return ""
    return recorded_run(path) or file_digest(path)


def recorded_run(path: Path) -> str:
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


_DIGESTS: dict[tuple[str, int, int], str] = {}


def file_digest(path: str | os.PathLike) -> str:
    """A short sha256 of a file's bytes (remembered per file size and modification time)."""
    path = Path(path).resolve()
    stat = path.stat()
    key = (str(path), stat.st_size, stat.st_mtime_ns)
    if key not in _DIGESTS:
        digest = hashlib.sha256()
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                digest.update(block)
        _DIGESTS[key] = digest.hexdigest()[:ID_LENGTH]
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
