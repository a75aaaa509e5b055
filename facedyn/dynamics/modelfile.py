"""Trained dynamics models (networks F and H) and their single-file format.

A model file never holds code, so loading one never runs any: it is

    8 bytes   magic b"FDYNMDL1"
    8 bytes   header length H, unsigned little-endian
    H bytes   JSON header: {"metadata": {...}, "arrays": {name: {dtype, shape, offset}},
              "checksums": {"metadata": sha256, "arrays": sha256}}
    ...       the arrays' raw little-endian bytes, back to back in header order, offsets
              relative to the end of the header

(the layout of safetensors, written with the standard library). Only plain numeric dtypes
are accepted; anything else, including a pickle or a torch checkpoint, is refused with
`ModelFileError` before any of its data is read.

Reading is safe against crafted files, not only against pickles: only regular files are
opened, the header size and every declared count (arrays, dimensions, layers, widths) are
bounded, the array table must tile the file exactly, and the architecture must match the
arrays present before a network is allocated, so a file can never make facedyn allocate
much more than its own size. Loading reads each array once, straight into an array of its
own, hashing the bytes as they arrive, and the model's network is those arrays
(facedyn.dynamics.network_weights: applied in NumPy, torch not imported; the torch module
built from them without a copy, `DynamicsModel.torch_network`, only to train or use a GPU),
so a load's peak is about the arrays themselves (benchmarks/bench_model_load_memory.py);
`describe_model` (`usdfacedyn inspect MODEL`) checks everything and builds nothing.
Version 2 stores SHA-256 checksums of the metadata (its canonical JSON) and of the arrays
(their table and bytes), verified on every load, so a damaged or edited file (flipped
weight signs, a changed frame rate) is refused. They detect changes, they do not authenticate an author. Version 1 files, written before
checksums, still load, with a warning in `DynamicsModel.warnings` saying to re-save them.

The metadata says what the model may be used on: its kind ("removal" for F, "synthesis"
for H, "response" for an actor's linear response, facedyn.dynamics.response), frame rate, feature windows (and for H the kind of skull-motion input), the
topology's fingerprint, skull landmarks and skin sample indices, plus how it was trained
(takes, settings, loss curve, validation errors). The arrays are the network's weights and
normalization, the neutral mesh and rigid region that propagation is rebuilt from, and
any kind-specific arrays (``DynamicsModel.arrays``, e.g. the uv neighbourhoods that H's
stretch features need). `ModelMismatch` is raised when a model meets a mesh or a take it
does not fit. Response files written before the kind existed say "synthesis" with
`calibration.response` "linear"; they load as kind "response".

A blend (kind "blend", `save_blend`) holds whole models in one file, each member's metadata
under `members` and its arrays under `member<i>/`: what `remove --model` takes to remove
the mean of their dynamics, as `--blend` does, or with `bands` their dynamics weighted per
frequency band (facedyn.dynamics.bands.BandWeights, as `calibrate` chooses them);
`load_models` reads it (and any one model).
"""
from __future__ import annotations

import hashlib
import json
import math
import struct
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.netspec import NetworkSpec
from facedyn.dynamics.network_weights import NetworkWeights
from facedyn.dynamics.skull_motion import SkullMotionInput
from facedyn.errors import FacedynError
from facedyn.io.errors import InputError, quoted
from facedyn.io.files import open_regular, write_atomically
from facedyn.performance import Topology

if TYPE_CHECKING:
    from facedyn.dynamics.bands import BandWeights
    from facedyn.dynamics.network import Network

MAGIC = b"FDYNMDL1"
FORMAT_VERSION = 2
UNCHECKED_VERSIONS = (1,)  # readable, but written before checksums
KINDS = ("removal", "synthesis", "response")
BLEND = "blend"
SUFFIXES = {"removal": ".removal", "synthesis": ".synthesis", "response": ".response", BLEND: ".blend"}
NETWORK_NAMES = {"removal": "F", "synthesis": "H", "response": "linear response (actor's)"}
FPS_RANGE = (1.0, 10000.0)
MAX_FILE_BYTES = 4 << 30
MAX_HEADER_BYTES = 16 << 20
MAX_ARRAYS = 256
MAX_DIMENSIONS = 4
MAX_HIDDEN_LAYERS = 16
MAX_LAYER_WIDTH = 1 << 16
MAX_WINDOW = 10000
CHUNK_BYTES = 512 << 20  # what one chunk of frames may allocate when a model is applied (affordable_frames)
FRAME_BYTES_FLOOR = 64 << 20  # what applying any model may allocate for one frame (see _check_sizes)
_SAMPLE_POSITIONS = "sample_positions"  # F's per-sample rest positions (facedyn.dynamics.removal.SAMPLE_POSITIONS)
_STRETCH_SAMPLES = "stretch/samples"  # H's stretch neighbourhoods' samples (facedyn.dynamics.synthesis)
MAX_MEMBERS = 8
PER_TAKE = "per-take"  # info["face"] of a person-independent removal model, its face set up per take (facedyn.dynamics.portable)
_DTYPES = {"float32": np.float32, "float64": np.float64, "int32": np.int32, "int64": np.int64}
_RESERVED = ("format", "version", "kind", "fps", "windows", "architecture", "topology_fingerprint", "point_count", "skull_landmarks", "skin_samples", "normalization", "skull_motion")


class ModelFileError(FacedynError):
    """The file is not a readable facedyn model."""


class ModelMismatch(FacedynError):
    """A model was asked to work on a mesh topology or frame rate it was not trained for."""


@dataclass
class DynamicsModel:
    kind: str  # "removal" (network F), "synthesis" (network H) or "response" (an actor's linear response)
    network: Network | NetworkWeights  # a torch Network (trained or built here), or the weights a file holds (`torch_network`)
    face: FaceSetup
    fps: float
    windows: dict  # {"skull": w_b, "skin": w_x, "target": w}
    info: dict = field(default_factory=dict)  # training description, loss curve, validation
    arrays: dict[str, np.ndarray] = field(default_factory=dict)  # kind-specific data (e.g. H's uv neighbourhoods)
    skull_motion: SkullMotionInput | None = None  # what the network reads of the skull; None = the paper's B(t) over windows["skull"]
    warnings: list[str] = field(default_factory=list)  # what loading could not verify (e.g. a file without checksums)
    frame: object = None  # a person-independent model set up for one take: its FaceFrame (facedyn.dynamics.portable)
    _propagator: object = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"model kind must be one of {KINDS}, got {self.kind!r}")

    @property
    def skull_input(self) -> SkullMotionInput:
        """The skull features the network reads, spelled out also for the paper's default."""
        return _skull_input(self.skull_motion, self.windows)

    @property
    def spec(self) -> NetworkSpec:
        """The network's shape (what feature_sizes and frame_bytes read, of a loaded model or a checked file)."""
        return self.network.spec

    @property
    def weights(self) -> NetworkWeights:
        """The network's weights as NumPy arrays, what applying the model on the CPU runs (no torch imported for a loaded model)."""
        return NetworkWeights.of(self.network)

    def torch_network(self) -> Network:
        """The network as a torch module, built once from a loaded model's weights (without a copy): for training or a GPU."""
        if isinstance(self.network, NetworkWeights):
            from facedyn.dynamics.network import Network

            self.network = Network.from_weights(self.network)
        return self.network

    @property
    def fingerprint(self) -> str:
        return self.face.fingerprint

    def check_compatible(self, topology: Topology | str | None = None, fps: float | None = None) -> None:
        """Raise ModelMismatch unless the topology (or its fingerprint) and fps match; a
        person-independent model (its face built per take, facedyn.dynamics.portable) fits any topology."""
        if topology is not None and self.info.get("face") != PER_TAKE:
            theirs = topology if isinstance(topology, str) else topology.fingerprint()
            if theirs != self.fingerprint:
                raise ModelMismatch(f"the {self.kind} model was trained on mesh topology {self.fingerprint}, but this mesh has topology {theirs}")
        if fps is not None and not abs(float(fps) - self.fps) <= 1e-6 * self.fps:
            raise ModelMismatch(f"the {self.kind} model was trained at {self.fps:g} fps, but this take runs at {float(fps):g} fps; its velocity windows would not match (resample the capture with `usdfacedyn import CAPTURE --fps {self.fps:g}`)")

    def propagator(self):
        """The sample-to-mesh propagation of this model's face, built once (its solve kept on disk for later runs)."""
        if self._propagator is None:
            from facedyn.dynamics.propagate import build_propagator
            from facedyn.dynamics.spread import Spread

            spread = Spread.from_arrays(self.arrays, len(self.face.samples), self.face.point_count)
            self._propagator = replace(build_propagator(self.face.rest_points, self.face.topology.triangles(), self.face.samples,
                                                        self.face.rigid_vertices, cache=True), spread=spread)
        return self._propagator


def _skull_input(skull_motion: SkullMotionInput | None, windows: dict) -> SkullMotionInput:
    """The recorded skull_motion input, or the paper's B(t): velocities over windows["skull"] either side."""
    if skull_motion is not None:
        return skull_motion
    return SkullMotionInput("velocity", windows["skull"], windows["skull"])


def checksums(metadata: dict, table: dict, data: Iterable[bytes]) -> dict[str, str]:
    """SHA-256 of the metadata's canonical JSON, and of the array table's plus the bytes."""
    arrays = hashlib.sha256(_canonical(table))
    for chunk in data:
        arrays.update(chunk)
    return {"metadata": hashlib.sha256(_canonical(metadata)).hexdigest(), "arrays": arrays.hexdigest()}


def _canonical(value) -> bytes:
    return json.dumps(value, sort_keys=True, separators=(",", ":"), ensure_ascii=True).encode()


def save_model(model: DynamicsModel, path) -> Path:
    """Write the model to ``path`` atomically (temporary file, then rename), mode 0644 under
    the usual umask, as format version FORMAT_VERSION with its checksums."""
    metadata, arrays = _contents(model)
    return _write(Path(path), metadata, arrays)


def save_blend(models: list, path, weights=None) -> Path:
    """Write a blend of models (each a removal model or a linear response, one mesh and frame
    rate) to ``path`` atomically: one file that removes the mean of their dynamics, or with
    `weights` (a BandWeights of as many members) their dynamics weighted per frequency band."""
    if len(models) < 2 or any(m.kind not in ("removal", "response") for m in models):
        raise ValueError(f"a blend holds two or more removal models or linear responses, got {[m.kind for m in models]}")
    if weights is not None and weights.members != len(models):
        raise ValueError(f"band weights of {weights.members} members for a blend of {len(models)}")
    for other in models[1:]:
        models[0].check_compatible(other.fingerprint, other.fps)
    metadata = {"format": "facedyn-model", "version": FORMAT_VERSION, "kind": BLEND, "members": []}
    if weights is not None and not weights.is_mean():
        metadata["bands"] = weights.to_json()
    arrays = {}
    for i, model in enumerate(models):
        member, member_arrays = _contents(model)
        metadata["members"].append(member)
        arrays.update({f"member{i}/{name}": value for name, value in member_arrays.items()})
    return _write(Path(path), metadata, arrays)


def _contents(model: DynamicsModel) -> tuple[dict, dict[str, np.ndarray]]:
    """(metadata, arrays) of one model as its file stores them."""
    arrays = {f"network/{k}": v for k, v in model.weights.state.items()}
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
    return json.loads(json.dumps(metadata)), arrays  # as a reader will see it (tuples as lists, ...)


def _write(path: Path, metadata: dict, arrays: dict[str, np.ndarray]) -> Path:
    """The file of a metadata header and its arrays, with their checksums, atomically."""
    table, blobs, offset = {}, [], 0
    for name, arr in arrays.items():
        dtype = arr.dtype.name
        if dtype not in _DTYPES:
            raise ValueError(f"array {name} has dtype {dtype}; a model file holds only {sorted(_DTYPES)}")
        blob = np.ascontiguousarray(arr, dtype=arr.dtype.newbyteorder("<")).tobytes()
        table[name] = {"dtype": dtype, "shape": list(arr.shape), "offset": offset}
        blobs.append(blob)
        offset += len(blob)
    header = json.dumps({"metadata": metadata, "arrays": table, "checksums": checksums(metadata, table, blobs)}).encode()
    header += b" " * (-len(header) % 8)
    if len(header) > MAX_HEADER_BYTES:
        raise ValueError(f"the model's metadata takes {len(header)} bytes, more than the {MAX_HEADER_BYTES} a model header may")
    path.parent.mkdir(parents=True, exist_ok=True)

    def write(out) -> None:
        out.write(MAGIC + struct.pack("<Q", len(header)) + header)
        for blob in blobs:
            out.write(blob)

    return write_atomically(path, write)


@dataclass(frozen=True)
class _Stored:
    """A model file as read and checked: what it says, its arrays, its checksums."""

    metadata: dict
    arrays: dict[str, np.ndarray]
    checksums: dict[str, str] | None  # None for versions before checksums
    size: int


def read_model_file(path) -> tuple[dict, dict[str, np.ndarray]]:
    """(metadata, arrays) of a model file, checked; nothing in it is ever executed."""
    stored = _read(Path(path))
    return stored.metadata, stored.arrays


def _read(path: Path) -> _Stored:
    """The checked file, its arrays read once: each straight into its own array, hashed as it
    arrives, so loading holds the arrays and nothing else the size of the file (no copy of
    the raw bytes, no byte-order copy on a little-endian machine)."""
    try:
        handle, size = open_regular(path)
    except InputError as exc:
        raise ModelFileError(f"cannot read model file {exc}") from None
    with handle:
        if size > MAX_FILE_BYTES:
            raise ModelFileError(f"{path} is {size} bytes, more than the {MAX_FILE_BYTES} a model file may be")
        prefix = handle.read(16)
        if prefix[:8] != MAGIC:
            raise ModelFileError(f"{path} is not a facedyn model file (it does not start with {MAGIC!r}); pickles and torch checkpoints are refused")
        if len(prefix) < 16:
            raise ModelFileError(f"{path} is truncated")
        (header_size,) = struct.unpack("<Q", prefix[8:16])
        if header_size > MAX_HEADER_BYTES:
            raise ModelFileError(f"{path} declares a header of {header_size} bytes, more than the {MAX_HEADER_BYTES} a model header may have")
        if header_size > size - 16:
            raise ModelFileError(f"{path} has a header of {header_size} bytes, more than the file holds")
        header = _header(path, handle.read(header_size))
        specs = _array_table(path, header["arrays"], size - 16 - header_size)
        metadata = header["metadata"]
        version = _version(path, metadata)
        digest = hashlib.sha256(_canonical(header["arrays"]))
        arrays = {name: _read_array(path, handle, dtype, shape, count, digest) for name, (dtype, shape, _, count) in specs.items()}
    stored_sums = header.get("checksums")
    if version in UNCHECKED_VERSIONS:
        sums = None
    else:
        sums = {"metadata": hashlib.sha256(_canonical(metadata)).hexdigest(), "arrays": digest.hexdigest()}
        for part in ("metadata", "arrays"):
            if not isinstance(stored_sums, dict) or stored_sums.get(part) != sums[part]:
                raise ModelFileError(f"{path}: its {part} do not match the checksum saved with them; the file was changed or damaged after it was written: re-save or retrain the model")
    for name, arr in arrays.items():
        if arr.dtype.kind == "f" and not _finite(arr):
            raise ModelFileError(f"{path}: array {name!r} holds NaN or infinite values")
    return _Stored(metadata, arrays, sums, size)


READ_BYTES = 8 << 20  # bytes read (and hashed) at a time


def _read_array(path: Path, handle, dtype: np.dtype, shape: tuple, count: int, digest) -> np.ndarray:
    """The next array of the file, read into an array of its own (native byte order), its bytes fed to `digest`."""
    arr = np.empty(count, dtype)
    raw = memoryview(arr.view(np.uint8))
    done = 0
    while done < len(raw):
        got = handle.readinto(raw[done:done + READ_BYTES])
        if not got:
            raise ModelFileError(f"{path} changed while it was read")
        digest.update(raw[done:done + got])
        done += got
    if not arr.dtype.isnative:
        arr = arr.byteswap().view(arr.dtype.newbyteorder("="))
    return arr.reshape(shape)


def _finite(arr: np.ndarray, block: int = 1 << 20) -> bool:
    """No NaN or infinity in arr, checked a block at a time (no mask the size of the array)."""
    flat = arr.reshape(-1)
    return all(np.isfinite(flat[i:i + block]).all() for i in range(0, flat.size, block))


def _header(path: Path, raw: bytes) -> dict:
    """The JSON header, checked for its three parts' types."""
    try:
        header = json.loads(raw)
    except (ValueError, RecursionError) as exc:  # RecursionError: nesting thousands deep
        raise ModelFileError(f"{path} has an unreadable header: {type(exc).__name__}: {str(exc)[:100]}") from None
    if not (isinstance(header, dict) and isinstance(header.get("metadata"), dict) and isinstance(header.get("arrays"), dict)):
        raise ModelFileError(f"{path} has an unreadable header: it needs 'metadata' and 'arrays' objects")
    return header


def _array_table(path: Path, table: dict, data_size: int) -> dict[str, tuple]:
    """{name: (dtype, shape, byte offset, element count)}: plain dtypes, bounded shapes,
    whole-number offsets, stored back to back and filling the data exactly."""
    if len(table) > MAX_ARRAYS:
        raise ModelFileError(f"{path} declares {len(table)} arrays, more than the {MAX_ARRAYS} a model may have")
    specs, expected = {}, 0
    for name, spec in table.items():
        if not (isinstance(spec, dict) and isinstance(spec.get("dtype"), str) and spec["dtype"] in _DTYPES
                and set(spec) == {"dtype", "shape", "offset"}):
            raise ModelFileError(f"{path}: array {name!r} has a bad entry {str(spec)[:100]} (dtypes allowed: {sorted(_DTYPES)})")
        shape, offset = spec["shape"], spec["offset"]
        if not (isinstance(shape, list) and len(shape) <= MAX_DIMENSIONS and all(_whole(s) and s >= 0 for s in shape)):
            raise ModelFileError(f"{path}: array {name!r} has shape {str(shape)[:100]}; a shape is up to {MAX_DIMENSIONS} whole numbers >= 0")
        if not _whole(offset):
            raise ModelFileError(f"{path}: array {name!r} has offset {offset!r}, not a whole number of bytes")
        if offset != expected:
            raise ModelFileError(f"{path}: array {name!r} starts at byte {offset}, not {expected} where the previous array ends")
        dtype = np.dtype(_DTYPES[spec["dtype"]]).newbyteorder("<")
        count = math.prod(shape)
        expected = offset + count * dtype.itemsize
        if expected > data_size:
            raise ModelFileError(f"{path}: array {name!r} lies outside the file (ends at byte {expected} of {data_size})")
        specs[name] = (dtype, tuple(shape), offset, count)
    if expected != data_size:
        raise ModelFileError(f"{path} holds {data_size - expected} bytes after its last array")
    return specs


def _whole(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _number(value) -> bool:
    """A finite JSON number (ints beyond float range, which math.isfinite cannot take, are not)."""
    if _whole(value):
        return abs(value) <= 2**63
    return isinstance(value, float) and math.isfinite(value)


def _version(path: Path, metadata: dict) -> int:
    version = metadata.get("version")
    if metadata.get("format") != "facedyn-model" or not (_whole(version) and (version == FORMAT_VERSION or version in UNCHECKED_VERSIONS)):
        readable = ", ".join(map(str, (*UNCHECKED_VERSIONS, FORMAT_VERSION)))
        raise ModelFileError(f"{path} is format {str(metadata.get('format'))[:40]!r} version {str(version)[:20]!r}; this facedyn reads facedyn-model versions {readable}")
    return version


def load_model(path, *, topology: Topology | str | None = None, fps: float | None = None) -> DynamicsModel:
    """Load a model; with ``topology``/``fps`` given, check that it fits them (ModelMismatch).
    A blend is refused here (ModelFileError): only removal reads one, through `load_models`."""
    stored = _read(Path(path))
    if stored.metadata.get("kind") == BLEND:
        raise ModelFileError(f"{path} is a blend of {len(_members(Path(path), stored))} removal models; only remove --model and "
                             "evaluate --removal take a blend")
    model = _build(Path(path), stored)
    model.check_compatible(topology, fps)
    return model


def load_models(path, *, topology: Topology | str | None = None, fps: float | None = None) -> tuple[list[DynamicsModel], BandWeights]:
    """([the model], its weight 1) of a model file, or a blend's members (each checked like a
    model) and how the blend weighs their removals (facedyn.dynamics.bands.BandWeights: the
    mean unless the blend declares bands)."""
    path = Path(path)
    stored = _read(path)
    if stored.metadata.get("kind") != BLEND:
        models = [_build(path, stored)]
    else:
        models = [_build(path, member) for member in _members(path, stored)]
    for model in models:
        model.check_compatible(topology, fps)
    return models, _blend_weights(path, stored, len(models))


def _blend_weights(path: Path, stored: _Stored, members: int) -> BandWeights:
    """A blend's declared band weights, checked (the mean when it declares none; weight 1 for one model)."""
    from facedyn.dynamics.bands import BandWeights

    if "bands" not in stored.metadata or stored.metadata.get("kind") != BLEND:
        return BandWeights.mean(members)
    try:
        weights = BandWeights.from_json(stored.metadata["bands"])
    except ValueError as error:
        raise ModelFileError(f"{path}: its band weights are not valid: {error}") from None
    if weights.members != members:
        raise ModelFileError(f"{path}: band weights for {weights.members} members in a blend of {members}")
    return weights


def _members(path: Path, stored: _Stored) -> list[_Stored]:
    """A checked blend's members, each as a stored model of its own (its checksums are the blend's)."""
    members = stored.metadata.get("members")
    if not (isinstance(members, list) and 2 <= len(members) <= MAX_MEMBERS and all(isinstance(m, dict) for m in members)):
        raise ModelFileError(f"{path}: a blend needs a list of 2 to {MAX_MEMBERS} member models, got {str(members)[:100]}")
    parts = [{name.split("/", 1)[1]: arr for name, arr in stored.arrays.items() if name.startswith(f"member{i}/")}
             for i in range(len(members))]
    if sum(map(len, parts)) != len(stored.arrays):
        raise ModelFileError(f"{path}: a blend holds arrays that belong to none of its {len(members)} members")
    for member in members:
        if member.get("kind") not in ("removal", "response") and not _legacy_response(member):
            raise ModelFileError(f"{path}: a blend member of kind {str(member.get('kind'))[:40]!r}; a blend holds removal models "
                                 "and linear responses")
    return [_Stored(member, arrays, stored.checksums, stored.size) for member, arrays in zip(members, parts)]


def _legacy_response(metadata: dict) -> bool:
    """A linear response written before the kind existed: a synthesis model so calibrated."""
    calibration = metadata.get("calibration")
    return metadata.get("kind") == "synthesis" and isinstance(calibration, dict) and calibration.get("response") == "linear"


@dataclass
class _Checked:
    """One stored model checked against its metadata, its network not built: what `inspect`
    shows without importing torch, and what `_build` makes a DynamicsModel of."""

    kind: str
    spec: NetworkSpec
    face: FaceSetup
    fps: float
    windows: dict
    info: dict
    arrays: dict[str, np.ndarray]  # kind-specific (the file's extra/ arrays)
    skull_motion: SkullMotionInput | None
    warnings: list[str]

    @property
    def skull_input(self) -> SkullMotionInput:
        return _skull_input(self.skull_motion, self.windows)

    @property
    def fingerprint(self) -> str:
        return self.face.fingerprint


def _build(path: Path, stored: _Stored) -> DynamicsModel:
    """The model a checked file describes, its network the stored weights (torch is not imported)."""
    checked = _check(path, stored)
    state = {name[len("network/"):]: value for name, value in stored.arrays.items() if name.startswith("network/")}
    try:
        network = NetworkWeights(checked.spec, state)
    except ValueError as exc:
        raise ModelFileError(f"{path} is an incomplete or inconsistent model: {type(exc).__name__}: {str(exc)[:200]}") from None
    return DynamicsModel(kind=checked.kind, network=network, face=checked.face, fps=checked.fps, windows=checked.windows,
                         info=checked.info, arrays=checked.arrays, skull_motion=checked.skull_motion, warnings=checked.warnings)


def _check(path: Path, stored: _Stored) -> _Checked:
    """The model a checked file describes, before its network is built; every inconsistency is a ModelFileError."""
    metadata, arrays = stored.metadata, stored.arrays
    try:
        spec = _architecture(path, metadata.get("architecture"), arrays)
        kind, fps, windows = metadata["kind"], metadata["fps"], metadata["windows"]
        kind = "response" if _legacy_response(metadata) else kind
        if kind not in KINDS:
            raise ModelFileError(f"{path}: kind {str(kind)[:40]!r} is none of {', '.join(KINDS)}")
        if not (_number(fps) and FPS_RANGE[0] <= fps <= FPS_RANGE[1]):
            raise ModelFileError(f"{path}: fps {str(fps)[:40]} is not a frame rate from {FPS_RANGE[0]:g} to {FPS_RANGE[1]:g}")
        if not (isinstance(windows, dict) and all(_whole(w) and 0 <= w <= MAX_WINDOW for w in windows.values())):
            raise ModelFileError(f"{path}: windows {str(windows)[:100]} are not whole numbers of frames from 0 to {MAX_WINDOW}")
        if "skull_motion" not in metadata and "skull" not in windows:
            raise ModelFileError(f"{path}: records neither its skull_motion input nor a skull window")
        if kind == "removal" and "skull" not in windows:
            raise ModelFileError(f"{path}: a removal model needs windows.skull, the frames its skin features span")
        _check_skull_motion(path, metadata.get("skull_motion"))
        face = FaceSetup(
            topology=_topology(path, arrays, metadata["point_count"]),
            rest_points=arrays["face/rest_points"],
            samples=_indices(path, "skin_samples", metadata["skin_samples"]),
            landmarks=_points(path, "skull_landmarks", metadata["skull_landmarks"]),
            rigid_vertices=arrays["face/rigid_vertices"],
        )
        model = _Checked(
            kind=kind,
            spec=spec,
            face=face,
            fps=float(fps),
            windows=dict(windows),
            info={k: v for k, v in metadata.items() if k not in _RESERVED},
            arrays={k[len("extra/"):]: v for k, v in arrays.items() if k.startswith("extra/")},
            skull_motion=SkullMotionInput.from_json(metadata["skull_motion"]) if "skull_motion" in metadata else None,
            warnings=[],
        )
    except (KeyError, TypeError, RuntimeError, ValueError) as exc:
        if isinstance(exc, FacedynError):
            raise
        raise ModelFileError(f"{path} is an incomplete or inconsistent model: {type(exc).__name__}: {str(exc)[:200]}") from None
    _check_sizes(path, model, stored.size)
    _check_spread(path, model)
    recorded = metadata.get("topology_fingerprint")
    if model.fingerprint != recorded:
        raise ModelFileError(f"{path}: its stored topology hashes to {model.fingerprint}, not the recorded {str(recorded)[:40]}")
    if stored.checksums is None:
        model.warnings.append(f"{path} is model format version {metadata['version']}, written without checksums, so damage to it cannot be detected; re-save it (load and save it with this facedyn) to add them")
    return model


def _check_spread(path: Path, model: "_Checked") -> None:
    """An actor's learned spread (facedyn.dynamics.spread), if the file carries one, fits its mesh."""
    from facedyn.dynamics.spread import Spread

    try:
        Spread.from_arrays(model.arrays, len(model.face.samples), model.face.point_count)
    except ValueError as error:
        raise ModelFileError(f"{path}: {error}") from None


def _check_skull_motion(path: Path, value) -> None:
    """A recorded skull_motion input, bounded like the windows, before its width is used."""
    if value is None:
        return
    if not (isinstance(value, dict) and all(_whole(value.get(k)) and 0 <= value[k] <= MAX_WINDOW for k in ("past", "future"))):
        raise ModelFileError(f"{path}: skull_motion {str(value)[:100]} needs past and future in whole frames from 0 to {MAX_WINDOW}")


def feature_sizes(model: DynamicsModel) -> dict[str, int]:
    """The network's input and output widths its metadata implies, derived as removal and synthesis build them.

    removal (F, one evaluation per skin sample): the skull features (landmarks x skull
    window frames x 3) plus the skin features (windows.skull as t-w..t+w, x 3) plus the
    sample's rest position when it reads one; 3 outputs. synthesis (H, one evaluation per
    frame): the skull features plus 2 stretch values per sample; 3 outputs per sample.
    """
    skull = len(model.face.landmarks) * model.skull_input.width * 3
    samples = len(model.face.samples)
    if model.kind == "removal":
        skin = (2 * model.windows["skull"] + 1) * 3 + (3 if _SAMPLE_POSITIONS in model.arrays else 0)
        return {"skull": skull, "skin": skin, "inputs": skull + skin, "outputs": 3, "items": samples}
    return {"skull": skull, "stretch": 2 * samples, "inputs": skull + 2 * samples, "outputs": 3 * samples, "items": 1}


def frame_bytes(model: DynamicsModel) -> dict[str, int]:
    """What applying the model allocates per frame of a take (bytes), and per frame of window context.

    per_frame: the network's inputs, hidden activations and outputs for every evaluation of
    a frame, plus the mesh-sized arrays a frame's result is propagated into (offsets,
    result points, the skull-space copy; float32). context: what each frame a window reaches
    beyond a chunk costs (the removal features are computed over a chunk's whole reach).
    """
    sizes = feature_sizes(model)
    spec = model.spec
    evaluations = sizes["items"] * (sizes["inputs"] + sum(spec.hidden) + spec.outputs)
    mesh = 3 * model.face.point_count * 3
    skull_windows = len(model.face.landmarks) * (2 * model.windows.get("skull", 0) + 1) * 3
    features = sizes["items"] * sizes["inputs"] + skull_windows if model.kind == "removal" else sizes["inputs"]
    per_frame = 4 * (evaluations + mesh + features)
    reach = 2 * model.windows.get("skull", 0) + 1 if model.kind == "removal" else 0
    return {"per_frame": per_frame, "context_frames": reach, "context": 4 * features}


def affordable_frames(model: DynamicsModel, chunk_frames: int) -> int:
    """chunk_frames, or fewer when a chunk of them would allocate more than CHUNK_BYTES (at least 1).

    A trained F needs about 2 MiB a frame, so its chunks keep their size; a model whose
    windows or widths are larger is applied a few frames at a time instead.
    """
    cost = frame_bytes(model)
    budget = CHUNK_BYTES - cost["context_frames"] * cost["context"]
    return max(1, min(int(chunk_frames), budget // cost["per_frame"]))


def _check_sizes(path: Path, model: DynamicsModel, file_bytes: int) -> None:
    """Every size the metadata implies matches the stored arrays, and one frame's work is bounded, before anything is applied.

    The bound: applying the model to one frame (with the window frames it reaches) may
    allocate at most 4 times the file's size, or FRAME_BYTES_FLOOR for small models (a
    trained F on a 11,000-point mesh needs about 2 MiB a frame).
    """
    if model.kind not in ("removal", "synthesis"):
        return
    spec, sizes = model.spec, feature_sizes(model)
    if model.kind == "removal":
        positions = model.arrays.get(_SAMPLE_POSITIONS)
        if positions is not None and positions.shape != (len(model.face.samples), 3):
            raise ModelFileError(f"{path}: its {_SAMPLE_POSITIONS} are {positions.shape}, not one 3-vector per skin sample "
                                 f"({len(model.face.samples)})")
        implied = (f"windows.skull {model.windows['skull']} (skin features of {sizes['skin']}) and "
                   f"{_skull_source(model)} ({sizes['skull']} skull features)")
    else:
        stretch = model.arrays.get(_STRETCH_SAMPLES)
        if stretch is not None and stretch.shape != (len(model.face.samples),):
            raise ModelFileError(f"{path}: its {_STRETCH_SAMPLES} array is {stretch.shape}, "
                                 f"not one entry per skin sample ({len(model.face.samples)})")
        implied = f"{_skull_source(model)} ({sizes['skull']} skull features) and {len(model.face.samples)} skin samples"
    if spec.inputs != sizes["inputs"]:
        raise ModelFileError(f"{path}: {implied} make {sizes['inputs']} network inputs, but its architecture has {spec.inputs}")
    if spec.outputs != sizes["outputs"]:
        raise ModelFileError(f"{path}: {len(model.face.samples)} skin samples make {sizes['outputs']} network outputs, "
                             f"but its architecture has {spec.outputs}")
    cost = frame_bytes(model)
    one_frame = cost["per_frame"] + cost["context_frames"] * cost["context"]
    limit = max(FRAME_BYTES_FLOOR, 4 * file_bytes)
    if one_frame > limit:
        raise ModelFileError(f"{path}: applying it would allocate {one_frame / 2**20:,.1f} MiB for a single frame "
                             f"({implied}), more than 4 times its {file_bytes / 2**20:,.1f} MiB file (or {FRAME_BYTES_FLOOR >> 20} MiB)")


def _skull_source(model: DynamicsModel) -> str:
    motion = model.skull_input
    where = "skull_motion" if model.skull_motion is not None else "windows.skull"
    return f"{where} {motion.kind} over {motion.width} frames x {len(model.face.landmarks)} landmarks"


def _architecture(path: Path, architecture, arrays: dict[str, np.ndarray]) -> NetworkSpec:
    """The network's shape, bounded and matching the stored weights, checked before any
    network is allocated (so a header cannot declare a network larger than the file)."""
    if not isinstance(architecture, dict) or not isinstance(architecture.get("hidden"), list):
        raise ModelFileError(f"{path}: architecture {str(architecture)[:100]} needs inputs, hidden (a list) and outputs")
    widths = [architecture.get("inputs"), *architecture["hidden"], architecture.get("outputs")]
    if len(widths) - 2 > MAX_HIDDEN_LAYERS or not all(_whole(w) and 1 <= w <= MAX_LAYER_WIDTH for w in widths):
        raise ModelFileError(f"{path}: architecture declares {len(widths) - 2} hidden layers, widths {quoted(str(widths), 60)}; "
                             f"a model has up to {MAX_HIDDEN_LAYERS} hidden layers of 1 to {MAX_LAYER_WIDTH} units")
    spec = NetworkSpec.from_json(architecture)
    expected = {"network/input_mean": (spec.inputs,), "network/input_std": (spec.inputs,),
                "network/output_mean": (spec.outputs,), "network/output_scale": (1,)}
    for i, (a, b) in enumerate(zip(widths[:-1], widths[1:])):
        expected[f"network/layers.{2 * i}.weight"] = (b, a)
        expected[f"network/layers.{2 * i}.bias"] = (b,)
    stored = {name: arr.shape for name, arr in arrays.items() if name.startswith("network/")}
    if stored != expected:
        differ = sorted(set(stored.items()) ^ set(expected.items()))[:3]
        raise ModelFileError(f"{path}: the stored network arrays do not match its architecture {widths} (e.g. {differ})")
    return spec


def _topology(path: Path, arrays: dict[str, np.ndarray], point_count) -> Topology:
    """The stored mesh topology, checked: polygons of 3+ corners indexing the rest points."""
    counts, indices = arrays["face/face_vertex_counts"], arrays["face/face_vertex_indices"]
    points = arrays["face/rest_points"]
    if not (_whole(point_count) and points.ndim == 2 and len(points) == point_count):
        raise ModelFileError(f"{path}: point_count {str(point_count)[:40]} does not match the {len(points)} rest points")
    if counts.ndim != 1 or indices.ndim != 1 or (counts.size and not 3 <= counts.min() <= counts.max() <= indices.size) \
            or int(counts.sum()) != indices.size:
        raise ModelFileError(f"{path}: the stored face counts and indices do not describe polygons")
    if indices.size and (indices.min() < 0 or indices.max() >= point_count):
        raise ModelFileError(f"{path}: the stored face indices leave the {point_count} rest points")
    return Topology(counts, indices)


def _indices(path: Path, name: str, values) -> np.ndarray:
    if not (isinstance(values, list) and all(_whole(v) and 0 <= v < 2**31 for v in values)):
        raise ModelFileError(f"{path}: {name} must be a list of vertex indices")
    return np.asarray(values, np.int64)


def _points(path: Path, name: str, values) -> np.ndarray:
    if not (isinstance(values, list) and all(isinstance(p, list) and len(p) == 3 and all(map(_number, p)) for p in values)):
        raise ModelFileError(f"{path}: {name} must be a list of finite (x, y, z) points")
    return np.asarray(values, np.float64).reshape(-1, 3)


def describe_model(path) -> dict:
    """What `usdfacedyn inspect MODEL` shows: the checked model's kind, what it fits, how it
    was trained and validated, and its integrity (checksums, or warnings without them)."""
    path = Path(path)
    stored = _read(path)
    if stored.metadata.get("kind") == BLEND:
        members = [_describe(path, member) for member in _members(path, stored)]
        weights = _blend_weights(path, stored, len(members))
        how = "the mean of " if weights.is_mean() else f"per frequency band (edges {', '.join(f'{e:g}' for e in weights.edges_hz)} Hz) a weighing of "
        return {"path": str(path), "format_version": stored.metadata["version"], "kind": BLEND,
                "network": how + " and ".join(m["network"] for m in members), "members": members,
                **({} if weights.is_mean() else {"bands": weights.to_json()}),
                "checksum": stored.checksums, "bytes": stored.size}
    return {"path": str(path), **_describe(path, stored), "checksum": stored.checksums, "bytes": stored.size}


def _describe(path: Path, stored: _Stored) -> dict:
    """One model's part of `describe_model`: read from the checked file, no network built (no torch imported)."""
    model = _check(path, stored)
    return {
        "format_version": stored.metadata["version"],
        "kind": model.kind,
        "network": NETWORK_NAMES[model.kind],
        **({"face": "built per take (person-independent: any mesh, no rig or actor needed; the stored face is one it was trained on)"}
           if model.info.get("face") == PER_TAKE else {}),
        "topology_fingerprint": model.fingerprint,
        "point_count": model.face.point_count,
        "fps": model.fps,
        "windows": model.windows,
        "skull_features": model.skull_input.to_json(),
        "samples": int(len(model.face.samples)),
        "landmarks": int(len(model.face.landmarks)),
        "rigid_vertices": int(len(model.face.rigid_vertices)),
        "architecture": model.spec.to_json(),
        "parameters": model.spec.parameter_count,
        "bytes_per_frame": frame_bytes(model)["per_frame"] if model.kind in ("removal", "synthesis") else None,
        "training": model.info.get("training"),
        **({"calibration": model.info["calibration"]} if model.kind == "response" else {}),
        **({"spread": model.info["spread"]} if "spread" in model.info else {}),  # an actor's (facedyn.dynamics.spread)
        "validation": model.info.get("validation"),
        "warnings": list(model.warnings),
    }
