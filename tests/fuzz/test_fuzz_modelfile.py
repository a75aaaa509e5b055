"""Model files, valid and mutated or crafted: a working model or a FacedynError naming the file.

Damaged files (truncated, bytes flipped or inserted, random bytes, a wrong header length)
and crafted ones (a header value replaced or a key dropped, with the checksums recomputed
or not; or only the free-form training record changed, which must still load) of small
removal and synthesis models.
"""
import functools
import json
import struct
import tempfile
from pathlib import Path

import numpy as np
import torch
from hypothesis import event, given
from hypothesis import strategies as st
from mutate import only_files, outcome

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.modelfile import DynamicsModel, checksums, describe_model, load_model, save_model
from facedyn.dynamics.network import Network, NetworkSpec
from facedyn.dynamics.skull_motion import SkullMotionInput
from facedyn.performance import Topology

ODD_VALUES = [float("nan"), float("inf"), -1, 0, 1, 1.5, 1e300, 10**20, -10**9, "x", "NaN", None, [], {}, True,
              [[0.0, 0.0, 0.0]] * 3, [10**6] * 4, {"inputs": 2}]
CATEGORIES = ("unchanged", "truncated", "flipped bytes", "stray bytes", "random bytes", "header length",
              "crafted value", "crafted value unsigned", "crafted key dropped", "crafted training record")


@functools.lru_cache(maxsize=None)
def model_file(kind: str) -> bytes:
    """The bytes of a small saved model: a 6 x 5 grid face, 6 skin samples, a tiny MLP."""
    x, y = np.meshgrid(np.arange(6.0), np.arange(5.0))
    points = np.stack([x.ravel(), y.ravel(), 0.1 * x.ravel() ** 2], axis=1)
    quads = [[r * 6 + c, r * 6 + c + 1, (r + 1) * 6 + c + 1, (r + 1) * 6 + c] for r in range(4) for c in range(5)]
    topology = Topology(np.full(len(quads), 4, np.int32), np.array(quads, np.int32).ravel())
    face = FaceSetup.build(topology, points, rigid_vertices=np.arange(6), sample_count=6)
    torch.manual_seed(0)
    landmarks = len(face.landmarks)  # widths as the metadata implies them (modelfile.feature_sizes)
    if kind == "removal":
        spec = NetworkSpec(landmarks * 5 * 3 + 5 * 3, (8, 8), 3)  # B(t) and X_i(t) over t-2..t+2
    else:
        spec = NetworkSpec(landmarks * 4 * 3 + 2 * 6, (8, 8), 18)  # accelerations over t-2..t+1, stretch of 6 samples
    network = Network(spec)
    windows = {"skull": 2, "skin": 2, "target": 2} if kind == "removal" else {"stretch_smoothing": 2}
    model = DynamicsModel(kind, network, face, 120.0, windows, {"training": {"takes": [{"name": "fuzz", "frames": 9}], "device": "cpu"}, "validation": None},
                          skull_motion=None if kind == "removal" else SkullMotionInput("acceleration", 2, 1))
    with tempfile.TemporaryDirectory() as folder:
        return save_model(model, Path(folder) / "model").read_bytes()


def _paths(value, prefix=()):
    """Every (key path) inside a JSON value, lists included, at most 50 items per list."""
    yield prefix
    if isinstance(value, dict):
        for key, item in value.items():
            yield from _paths(item, prefix + (key,))
    elif isinstance(value, list):
        for index, item in enumerate(value[:50]):
            yield from _paths(item, prefix + (index,))


@st.composite
def damaged(draw, blob: bytes) -> bytes:
    category = draw(st.sampled_from(CATEGORIES))
    event(f"mutation: {category}")
    if category == "unchanged":
        return blob
    if category == "truncated":
        return blob[: draw(st.integers(0, len(blob) - 1))]
    if category == "flipped bytes":
        data = bytearray(blob)
        for _ in range(draw(st.integers(1, 4))):
            data[draw(st.integers(0, len(data) - 1))] ^= draw(st.integers(1, 255))
        return bytes(data)
    if category == "stray bytes":
        at = draw(st.integers(0, len(blob)))
        return blob[:at] + draw(st.binary(min_size=1, max_size=16)) + blob[at:]
    if category == "random bytes":
        return draw(st.sampled_from([b"", b"FDYNMDL1"])) + draw(st.binary(max_size=512))
    if category == "header length":
        return blob[:8] + struct.pack("<Q", draw(st.integers(0, 2**64 - 1))) + blob[16:]
    (length,) = struct.unpack("<Q", blob[8:16])
    header, data = json.loads(blob[16:16 + length]), blob[16 + length:]
    if category == "crafted training record":  # free-form: any JSON loads
        paths = [("metadata",) + p for p in _paths({"training": header["metadata"]["training"]}) if p]
    else:
        paths = [p for p in _paths({"metadata": header["metadata"], "arrays": header["arrays"]}) if p]
    path = paths[draw(st.integers(0, len(paths) - 1))]
    event(f"crafted: {path[0]}/{path[1] if len(path) > 1 else ''}")
    target = header
    for key in path[:-1]:
        target = target[key]
    if category == "crafted key dropped" and isinstance(target, dict):
        del target[path[-1]]
    else:
        target[path[-1]] = draw(st.sampled_from(ODD_VALUES))
    if category != "crafted value unsigned":
        header["checksums"] = checksums(header.get("metadata"), header.get("arrays"), [data])
    text = json.dumps(header).encode()
    return blob[:8] + struct.pack("<Q", len(text)) + text + data


@given(st.data())
def test_model_files_load_or_give_a_clear_error(data):
    kind = data.draw(st.sampled_from(["removal", "synthesis"]))
    raw = data.draw(damaged(model_file(kind)))
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "actor.model"
        path.write_bytes(raw)
        model = outcome([path], lambda: load_model(path))
        if model is not None:
            assert np.isfinite(model.weights.forward(np.zeros((4, model.network.spec.inputs), np.float32))).all()
            assert describe_model(path)["kind"] == model.kind and 1 <= model.fps <= 10000
            again = load_model(save_model(model, Path(folder) / "resaved.model"))  # what loads, saves and loads again
            assert again.fingerprint == model.fingerprint and again.warnings == []
            only_files(Path(folder), {"actor.model", "resaved.model"})
        else:
            only_files(Path(folder), {"actor.model"})


SIZE_FIELDS = ("windows.skull", "windows (another)", "skull_motion", "skull_landmarks", "skin_samples", "architecture.inputs")


@st.composite
def crafted_sizes(draw, blob: bytes) -> bytes:
    """A model whose metadata implies sizes (windows, skull-motion spans, landmarks, samples, widths) other than
    its arrays hold, with valid checksums: integrity proves nothing about sanity."""
    (length,) = struct.unpack("<Q", blob[8:16])
    header, data = json.loads(blob[16:16 + length]), blob[16 + length:]
    metadata = header["metadata"]
    field = draw(st.sampled_from(SIZE_FIELDS))
    event(f"crafted size: {field}")
    if field == "windows.skull":
        metadata["windows"]["skull"] = draw(st.sampled_from([0, 1, 3, 100, 10000, 10001]))
    elif field == "windows (another)":  # the skin and target windows of F, H's stretch smoothing: 10,000 frames on an 8-frame take
        key = draw(st.sampled_from(sorted(k for k in metadata["windows"] if k != "skull")))
        metadata["windows"][key] = draw(st.sampled_from([0, 1, 100, 10000, 10001]))
    elif field == "skull_motion":
        metadata["skull_motion"] = {"kind": draw(st.sampled_from(["velocity", "acceleration"])),
                                    "past": draw(st.sampled_from([0, 1, 2, 30, 10000, 10**9])),
                                    "future": draw(st.sampled_from([0, 1, 10, 10000, 10**9]))}
    elif field == "skull_landmarks":
        count = draw(st.integers(1, 12))
        metadata["skull_landmarks"] = [[float(i), float(i * i % 5), float(i % 3)] for i in range(count)]
    elif field == "skin_samples":
        metadata["skin_samples"] = draw(st.lists(st.integers(6, 29), min_size=1, max_size=20, unique=True))
    else:
        metadata["architecture"]["inputs"] = draw(st.sampled_from([1, 11, 13, 63, 10**5]))
    header["checksums"] = checksums(metadata, header["arrays"], [data])
    text = json.dumps(header).encode()
    return blob[:8] + struct.pack("<Q", len(text)) + text + data


@given(st.data())
def test_sizes_the_metadata_implies_match_the_arrays_before_anything_is_allocated(data):
    """A crafted size loads only where every derived width matches the arrays and a frame's work is bounded;
    what loads then runs on a take without allocating more than a chunk's budget."""
    from facedyn.dynamics import modelfile
    from facedyn.dynamics.removal import remove_dynamics
    from facedyn.dynamics.synthesis import synthesize_dynamics

    kind = data.draw(st.sampled_from(["removal", "synthesis"]))
    raw = data.draw(crafted_sizes(model_file(kind)))
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "actor.model"
        path.write_bytes(raw)
        model = outcome([path], lambda: load_model(path))
        if model is None:
            return
        sizes = modelfile.feature_sizes(model)
        assert (sizes["inputs"], sizes["outputs"]) == (model.network.spec.inputs, model.network.spec.outputs)
        cost = modelfile.frame_bytes(model)
        assert cost["per_frame"] + cost["context_frames"] * cost["context"] <= max(modelfile.FRAME_BYTES_FLOOR, 4 * len(raw))
        rest = model.face.rest_points.astype(np.float32)
        frames = np.stack([rest + np.float32(0.01 * i) for i in range(8)])
        apply = remove_dynamics if kind == "removal" else synthesize_dynamics
        if kind == "synthesis" and not any(k.startswith("stretch/") for k in model.arrays):
            return  # this small H holds no stretch neighbourhoods to apply
        points, offsets = outcome([path], lambda: apply(frames, None, None, model.fps, model, backend="numpy", device="cpu"))
        assert np.isfinite(offsets).all()
