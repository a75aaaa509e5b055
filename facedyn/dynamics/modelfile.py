"""Trained dynamics models (networks F and H) and their single-file format.

A model file never holds code, so loading one never runs any: it is

    8 bytes   magic b"FDYNMDL1"
    8 bytes   header length H, unsigned little-endian
    H bytes   JSON header: {"metadata": {...}, "arrays": {name: {dtype, shape, offset}}}
    ...       the arrays' raw little-endian bytes, offsets relative to the end of the header

(the layout of safetensors, written with the standard library). Only plain numeric dtypes
are accepted; anything else, including a pickle or a torch checkpoint, is refused with
`ModelFileError` before any of its data is read.

The metadata says what the model may be used on: its kind ("removal" for F, "synthesis"
for H), frame rate, feature windows (and for H the kind of skull-motion input), the topology's fingerprint, skull landmarks and skin
sample indices, plus how it was trained (takes, settings, loss curve, validation errors).
The arrays are the network's weights and normalization, the neutral mesh and rigid region
that propagation is rebuilt from, and any kind-specific arrays (``DynamicsModel.arrays``,
e.g. the uv neighbourhoods that H's stretch features need).
`ModelMismatch` is raised when a model meets a mesh or a take it does not fit.
"""
from __future__ import annotations

import json
import os
import struct
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.network import Network, NetworkSpec
from facedyn.dynamics.skull_motion import SkullMotionInput
from facedyn.errors import FacedynError
from facedyn.performance import Topology

MAGIC = b"FDYNMDL1"
FORMAT_VERSION = 1
KINDS = ("removal", "synthesis")
_DTYPES = {"float32": np.float32, "float64": np.float64, "int32": np.int32, "int64": np.int64}
_MAX_HEADER = 64 << 20
_RESERVED = ("format", "version", "kind", "fps", "windows", "architecture", "topology_fingerprint", "point_count", "skull_landmarks", "skin_samples", "normalization", "skull_motion")


class ModelFileError(FacedynError):
    """The file is not a readable facedyn model."""


class ModelMismatch(FacedynError):
    """A model was asked to work on a mesh topology or frame rate it was not trained for."""


@dataclass
class DynamicsModel:
    kind: str  # "removal" (network F) or "synthesis" (network H)
    network: Network
    face: FaceSetup
    fps: float
    windows: dict  # {"skull": w_b, "skin": w_x, "target": w}
    info: dict = field(default_factory=dict)  # training description, loss curve, validation
    arrays: dict[str, np.ndarray] = field(default_factory=dict)  # kind-specific data (e.g. H's uv neighbourhoods)
    skull_motion: SkullMotionInput | None = None  # what the network reads of the skull; None = the paper's B(t) over windows["skull"]
    _propagator: object = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"model kind must be one of {KINDS}, got {self.kind!r}")

    @property
    def skull_input(self) -> SkullMotionInput:
        """The skull features the network reads, spelled out also for the paper's default."""
        if self.skull_motion is not None:
            return self.skull_motion
        return SkullMotionInput("velocity", self.windows["skull"], self.windows["skull"])

    @property
    def fingerprint(self) -> str:
        return self.face.fingerprint

    def check_compatible(self, topology: Topology | str | None = None, fps: float | None = None) -> None:
        """Raise ModelMismatch unless the topology (or its fingerprint) and fps match."""
        if topology is not None:
            theirs = topology if isinstance(topology, str) else topology.fingerprint()
            if theirs != self.fingerprint:
                raise ModelMismatch(f"the {self.kind} model was trained on mesh topology {self.fingerprint}, but this mesh has topology {theirs}")
        if fps is not None and abs(float(fps) - self.fps) > 1e-6 * self.fps:
            raise ModelMismatch(f"the {self.kind} model was trained at {self.fps:g} fps, but this take runs at {float(fps):g} fps; its velocity windows would not match")

    def propagator(self):
        """The sample-to-mesh propagation of this model's face, built once."""
        if self._propagator is None:
            from facedyn.dynamics.propagate import build_propagator

            self._propagator = build_propagator(self.face.rest_points, self.face.topology.triangles(), self.face.samples, self.face.rigid_vertices)
        return self._propagator


def save_model(model: DynamicsModel, path) -> Path:
    """Write the model to ``path`` atomically (temporary file, then rename)."""
    path = Path(path)
    arrays = {f"network/{k}": v.detach().cpu().numpy() for k, v in model.network.state_dict().items()}
    face = model.face
    arrays.update({
        "face/rest_points": face.rest_points.astype(np.float64),
        "face/face_vertex_counts": np.asarray(face.topology.face_vertex_counts, np.int32),
        "face/face_vertex_indices": np.asarray(face.topology.face_vertex_indices, np.int32),
        "face/rigid_vertices": face.rigid_vertices.astype(np.int32),
    })
    arrays.update({f"extra/{name}": np.asarray(value) for name, value in model.arrays.items()})
    clash = set(model.info) & set(_RESERVED)
    if clash:
        raise ValueError(f"model info may not use the reserved metadata keys {sorted(clash)}")
    metadata = {
        "format": "facedyn-model",
        "version": FORMAT_VERSION,
        "kind": model.kind,
        "fps": model.fps,
        "windows": model.windows,
        "architecture": model.network.spec.to_json(),
        "topology_fingerprint": face.fingerprint,
        "point_count": face.point_count,
        "skull_landmarks": face.landmarks.tolist(),
        "skin_samples": face.samples.tolist(),
        "normalization": ["network/input_mean", "network/input_std", "network/output_mean", "network/output_scale"],
        **({"skull_motion": model.skull_motion.to_json()} if model.skull_motion is not None else {}),
        **model.info,
    }
    table, offset = {}, 0
    for name, arr in arrays.items():
        arr = np.ascontiguousarray(arr)
        dtype = arr.dtype.name
        if dtype not in _DTYPES:
            raise ValueError(f"array {name} has dtype {dtype}; a model file holds only {sorted(_DTYPES)}")
        arrays[name] = arr
        table[name] = {"dtype": dtype, "shape": list(arr.shape), "offset": offset}
        offset += arr.nbytes
    header = json.dumps({"metadata": metadata, "arrays": table}).encode()
    header += b" " * (-len(header) % 8)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name + ".", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as out:
            out.write(MAGIC + struct.pack("<Q", len(header)) + header)
            for arr in arrays.values():
                out.write(arr.astype(arr.dtype.newbyteorder("<"), copy=False).tobytes())
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise
    return path


def read_model_file(path) -> tuple[dict, dict[str, np.ndarray]]:
    """(metadata, arrays) of a model file, checked; nothing in it is ever executed."""
    path = Path(path)
    try:
        blob = path.read_bytes()
    except OSError as exc:
        raise ModelFileError(f"cannot read model file {path}: {exc.strerror}") from exc
    if blob[:8] != MAGIC:
        raise ModelFileError(f"{path} is not a facedyn model file (it does not start with {MAGIC!r}); pickles and torch checkpoints are refused")
    if len(blob) < 16:
        raise ModelFileError(f"{path} is truncated")
    (size,) = struct.unpack("<Q", blob[8:16])
    if size > min(_MAX_HEADER, len(blob) - 16):
        raise ModelFileError(f"{path} has a header of {size} bytes, more than the file holds")
    try:
        header = json.loads(blob[16: 16 + size])
        metadata, table = header["metadata"], header["arrays"]
    except (ValueError, KeyError, TypeError) as exc:
        raise ModelFileError(f"{path} has an unreadable header: {exc}") from exc
    data = memoryview(blob)[16 + size:]
    arrays = {}
    for name, spec in table.items():
        try:
            dtype = np.dtype(_DTYPES[spec["dtype"]]).newbyteorder("<")
            shape = tuple(int(s) for s in spec["shape"])
            offset = int(spec["offset"])
        except (KeyError, TypeError, ValueError) as exc:
            raise ModelFileError(f"{path}: array {name!r} has a bad entry {spec!r} (dtypes allowed: {sorted(_DTYPES)})") from exc
        count = int(np.prod(shape)) if shape else 1
        end = offset + count * dtype.itemsize
        if offset < 0 or any(s < 0 for s in shape) or end > len(data):
            raise ModelFileError(f"{path}: array {name!r} lies outside the file")
        arrays[name] = np.frombuffer(data[offset:end], dtype=dtype).reshape(shape).astype(dtype.newbyteorder("="))
    return metadata, arrays


def load_model(path, *, topology: Topology | str | None = None, fps: float | None = None) -> DynamicsModel:
    """Load a model; with ``topology``/``fps`` given, check that it fits them (ModelMismatch)."""
    metadata, arrays = read_model_file(path)
    if metadata.get("format") != "facedyn-model" or metadata.get("version") != FORMAT_VERSION:
        raise ModelFileError(f"{path} is format {metadata.get('format')!r} version {metadata.get('version')!r}; this facedyn reads facedyn-model version {FORMAT_VERSION}")
    try:
        spec = NetworkSpec.from_json(metadata["architecture"])
        network = Network(spec)
        state = {k[len("network/"):]: torch.from_numpy(v) for k, v in arrays.items() if k.startswith("network/")}
        network.load_state_dict(state)
        face = FaceSetup(
            topology=Topology(arrays["face/face_vertex_counts"], arrays["face/face_vertex_indices"]),
            rest_points=arrays["face/rest_points"],
            samples=np.asarray(metadata["skin_samples"], np.int32),
            landmarks=np.asarray(metadata["skull_landmarks"], np.float64),
            rigid_vertices=arrays["face/rigid_vertices"],
        )
        model = DynamicsModel(
            kind=metadata["kind"],
            network=network,
            face=face,
            fps=float(metadata["fps"]),
            windows={k: int(v) for k, v in metadata["windows"].items()},
            info={k: v for k, v in metadata.items() if k not in _RESERVED},
            arrays={k[len("extra/"):]: v for k, v in arrays.items() if k.startswith("extra/")},
            skull_motion=_skull_motion(metadata),
        )
    except (KeyError, TypeError, RuntimeError, ValueError) as exc:
        if isinstance(exc, FacedynError):
            raise
        raise ModelFileError(f"{path} is an incomplete or inconsistent model: {exc}") from exc
    if model.fingerprint != metadata["topology_fingerprint"]:
        raise ModelFileError(f"{path}: its stored topology hashes to {model.fingerprint}, not the recorded {metadata['topology_fingerprint']}")
    network.eval()
    model.check_compatible(topology, fps)
    return model


def _skull_motion(metadata: dict) -> SkullMotionInput | None:
    """The recorded skull input; None (the paper's B(t)) for files that record none."""
    return SkullMotionInput.from_json(metadata["skull_motion"]) if "skull_motion" in metadata else None
