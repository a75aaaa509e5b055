"""Model files: round trip, refusing foreign files and pickles, mismatch errors."""
import hashlib
import json
import os
import pickle
import stat
import struct

import numpy as np
import pytest
import torch
from synthetic_face import curved_sheet, top_rows

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.modelfile import (
    DynamicsModel, ModelFileError, ModelMismatch, checksums, describe_model, load_model, read_model_file, save_model,
)
from facedyn.dynamics.network import SYNTHESIS_HIDDEN, Network, NetworkSpec, removal_spec
from facedyn.dynamics.skull_motion import SkullMotionInput


def make_model(kind="removal", spec=None, skull_motion=None):
    pts, topo = curved_sheet(10, 8)
    face = FaceSetup.build(topo, pts, rigid_vertices=top_rows(10, 8, 2), sample_count=12)
    torch.manual_seed(0)
    net = Network(spec or removal_spec())
    rng = np.random.default_rng(0)
    net.set_normalization(rng.normal(size=net.spec.inputs), rng.uniform(0.5, 2, net.spec.inputs), rng.normal(size=net.spec.outputs), 0.3)
    info = {"training": {"takes": [{"name": "walk", "frames": 300}]}, "validation": {"rms_cm": 0.01}, "loss_curve": [{"epoch": 1, "train_loss": 1.0, "val_loss": 2.0}]}
    windows = {"skull": 10, "skin": 10, "target": 10} if kind == "removal" else {"stretch_smoothing": 10}
    return DynamicsModel(kind, net, face, 120.0, windows, info, skull_motion=skull_motion)


def assert_same_network(loaded, model):
    """The loaded model holds the saved weights, bit for bit (as NumPy arrays: loading imports no torch)."""
    assert loaded.weights.state.keys() == model.weights.state.keys()
    for name, value in model.weights.state.items():
        np.testing.assert_array_equal(loaded.weights.state[name], value)


def test_round_trip(tmp_path):
    model = make_model()
    path = save_model(model, tmp_path / "actor.fdyn")
    loaded = load_model(path, topology=model.face.topology, fps=120.0)
    assert loaded.kind == "removal" and loaded.fps == 120.0 and loaded.windows == model.windows
    assert loaded.info == model.info and loaded.fingerprint == model.fingerprint
    np.testing.assert_array_equal(loaded.face.samples, model.face.samples)
    np.testing.assert_allclose(loaded.face.landmarks, model.face.landmarks)
    np.testing.assert_array_equal(loaded.face.rigid_vertices, model.face.rigid_vertices)
    assert_same_network(loaded, model)
    metadata, arrays = read_model_file(path)
    assert metadata["topology_fingerprint"] == model.fingerprint
    assert metadata["architecture"] == {"inputs": 378, "hidden": [128, 128], "outputs": 3, "activation": "relu"}
    assert all(name in arrays for name in metadata["normalization"])


def test_synthesis_networks_use_the_same_file(tmp_path):
    samples = 12
    motion = SkullMotionInput("acceleration", 30, 10)
    model = make_model("synthesis", NetworkSpec(5 * 41 * 3 + 2 * samples, SYNTHESIS_HIDDEN, 3 * samples), motion)
    model.arrays["stretch_neighbours"] = np.arange(samples * 4, dtype=np.int32).reshape(samples, 4)
    loaded = load_model(save_model(model, tmp_path / "h.fdyn"))
    assert loaded.kind == "synthesis" and loaded.network.spec == model.network.spec
    assert loaded.skull_motion == motion and loaded.windows == {"stretch_smoothing": 10}
    np.testing.assert_array_equal(loaded.arrays["stretch_neighbours"], model.arrays["stretch_neighbours"])


def test_files_without_a_skull_motion_record_read_as_the_papers_velocities(tmp_path):
    """Files written before facedyn recorded the skull input used B(t) over windows['skull']."""
    samples = 12
    model = make_model("synthesis", NetworkSpec(5 * 15 * 3 + 2 * samples, SYNTHESIS_HIDDEN, 3 * samples), SkullMotionInput("velocity", 7, 7))
    blob = save_model(model, tmp_path / "new.fdyn").read_bytes()
    (length,) = struct.unpack("<Q", blob[8:16])
    header = json.loads(blob[16:16 + length])
    del header["metadata"]["skull_motion"]
    header["metadata"]["windows"] = {"skull": 7, "stretch_smoothing": 10}
    header["checksums"] = checksums(header["metadata"], header["arrays"], [blob[16 + length:]])
    old = json.dumps(header).encode()
    (tmp_path / "old.fdyn").write_bytes(blob[:8] + struct.pack("<Q", len(old)) + old + blob[16 + length:])
    loaded = load_model(tmp_path / "old.fdyn")
    assert loaded.skull_motion is None and loaded.skull_input == SkullMotionInput("velocity", 7, 7)


def test_a_removal_model_records_facedyns_skull_input_when_it_has_one(tmp_path):
    model = make_model("removal", removal_spec(615), SkullMotionInput())
    loaded = load_model(save_model(model, tmp_path / "f.fdyn"))
    assert loaded.skull_motion == SkullMotionInput() and loaded.skull_input == SkullMotionInput()
    assert load_model(save_model(make_model(), tmp_path / "g.fdyn")).skull_input == SkullMotionInput("velocity", 10, 10)


def test_mismatched_topology_or_frame_rate_is_refused(tmp_path):
    model = make_model()
    path = save_model(model, tmp_path / "actor.fdyn")
    _, other = curved_sheet(11, 8)
    with pytest.raises(ModelMismatch) as err:
        load_model(path, topology=other)
    assert model.fingerprint in str(err.value) and other.fingerprint() in str(err.value)
    with pytest.raises(ModelMismatch, match="trained at 120 fps.*runs at 96 fps.*import CAPTURE --fps 120"):
        load_model(path, fps=96.0)
    assert issubclass(ModelMismatch, ValueError)


class Exploit:
    def __reduce__(self):
        import os

        return (os.system, ("touch pwned-by-model-file",))


def test_pickles_and_torch_checkpoints_are_refused_unread(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "evil.fdyn").write_bytes(pickle.dumps({"weights": Exploit()}))
    torch.save(make_model().network, tmp_path / "checkpoint.pt")
    for name in ("evil.fdyn", "checkpoint.pt"):
        with pytest.raises(ModelFileError, match="not a facedyn model file"):
            load_model(tmp_path / name)
    assert not (tmp_path / "pwned-by-model-file").exists()


def test_our_header_with_a_pickle_payload_is_refused(tmp_path):
    header = json.dumps({"metadata": {}, "arrays": {"network/x": {"dtype": "object", "shape": [1], "offset": 0}}}).encode()
    (tmp_path / "m.fdyn").write_bytes(b"FDYNMDL1" + struct.pack("<Q", len(header)) + header + pickle.dumps(Exploit()))
    with pytest.raises(ModelFileError, match="dtypes allowed"):
        load_model(tmp_path / "m.fdyn")


def test_truncated_and_tampered_files_are_refused(tmp_path):
    path = save_model(make_model(), tmp_path / "actor.fdyn")
    blob = path.read_bytes()
    (tmp_path / "short.fdyn").write_bytes(blob[: len(blob) // 2])
    with pytest.raises(ModelFileError, match="outside the file"):
        load_model(tmp_path / "short.fdyn")
    with pytest.raises(ModelFileError, match="cannot read"):
        load_model(tmp_path / "missing.fdyn")


def _parts(blob):
    (length,) = struct.unpack("<Q", blob[8:16])
    return json.loads(blob[16:16 + length]), blob[16 + length:]


def craft(path, blob, edit=None, data=None, sign=True):
    """Write `blob` with its header edited by `edit(header)` (and its data replaced), with
    checksums recomputed when `sign`: a crafted file, not a damaged one."""
    header, old_data = _parts(blob)
    data = old_data if data is None else data
    if edit is not None:
        edit(header)
    if sign:
        header["checksums"] = checksums(header["metadata"], header["arrays"], [data])
    text = json.dumps(header).encode()
    path.write_bytes(b"FDYNMDL1" + struct.pack("<Q", len(text)) + text + data)
    return path


def test_models_are_written_like_layers_and_leave_nothing_behind(tmp_path):
    old = os.umask(0o022)
    try:
        path = save_model(make_model(), tmp_path / "models" / "actor.removal")
    finally:
        os.umask(old)
    assert stat.S_IMODE(path.stat().st_mode) == 0o644
    assert [p.name for p in path.parent.iterdir()] == ["actor.removal"]
    model = make_model()
    model.info["format"] = "mine"
    with pytest.raises(ValueError, match="reserved metadata keys"):
        save_model(model, path)
    assert [p.name for p in path.parent.iterdir()] == ["actor.removal"]
    assert save_model(make_model(), tmp_path / "again").read_bytes() == path.read_bytes()  # same model, same bytes


def test_changed_weights_or_metadata_fail_their_checksums(tmp_path):
    blob = save_model(make_model(), tmp_path / "actor.fdyn").read_bytes()
    header, data = _parts(blob)
    weight = header["arrays"]["network/layers.4.weight"]
    start, end = weight["offset"], weight["offset"] + 4 * int(np.prod(weight["shape"]))
    flipped = np.frombuffer(data[start:end], "<f4") * -1  # the output layer's signs flipped
    damaged = data[:start] + flipped.astype("<f4").tobytes() + data[end:]
    with pytest.raises(ModelFileError) as error:
        load_model(craft(tmp_path / "flipped.fdyn", blob, data=damaged, sign=False))
    assert str(error.value) == (f"{tmp_path / 'flipped.fdyn'}: its arrays do not match the checksum saved with them; the file was "
                                "changed or damaged after it was written: re-save or retrain the model")
    with pytest.raises(ModelFileError, match="its metadata do not match the checksum"):
        load_model(craft(tmp_path / "fps.fdyn", blob, lambda h: h["metadata"].update(fps=96.0), sign=False))
    with pytest.raises(ModelFileError, match="its metadata do not match the checksum"):
        load_model(craft(tmp_path / "none.fdyn", blob, lambda h: h.pop("checksums"), sign=False))


def _set(*keys_and_value):
    *keys, value = keys_and_value

    def edit(header):
        target = header
        for key in keys[:-1]:
            target = target[key]
        target[keys[-1]] = value
    return edit


@pytest.mark.parametrize(
    "edit, message",
    [
        (_set("metadata", "fps", float("nan")), "fps nan is not a frame rate from 1 to 10000"),
        (_set("metadata", "fps", "NaN"), "fps NaN is not a frame rate"),
        (_set("metadata", "fps", 0), "fps 0 is not a frame rate"),
        (_set("metadata", "fps", 1e300), "fps 1e[+]300 is not a frame rate"),
        (_set("metadata", "fps", True), "fps True is not a frame rate"),
        (_set("metadata", "windows", "skull", 1.5), "are not whole numbers of frames"),
        (_set("metadata", "kind", "dance"), "kind 'dance' is none of removal, synthesis"),
        (_set("metadata", "architecture", "hidden", [128] * 100_000), "a model has up to 16 hidden layers"),
        (_set("metadata", "architecture", "hidden", [10**9, 128]), "of 1 to 65536 units"),
        (_set("metadata", "architecture", "hidden", [128, 64]), "stored network arrays do not match its architecture"),
        (_set("metadata", "skin_samples", [0.5, 2]), "skin_samples must be a list of vertex indices"),
        (_set("metadata", "skin_samples", [10**20]), "skin_samples must be a list of vertex indices"),
        (_set("metadata", "skull_landmarks", [[10**400, 0, 0]] * 3), "skull_landmarks must be a list of finite"),
        (_set("metadata", "skull_landmarks", [[0, 0, "nan"]] * 3), "skull_landmarks must be a list of finite"),
        (_set("metadata", "point_count", 7), "point_count 7 does not match the 80 rest points"),
        (lambda h: h["metadata"].pop("topology_fingerprint"), "its stored topology hashes to [0-9a-f]{16}, not the recorded None"),
        (_set("metadata", "version", True), "version 'True'; this facedyn reads facedyn-model versions 1, 2"),
        (_set("metadata", "version", 3), "version '3'; this facedyn reads"),
        (_set("arrays", "network/input_mean", "offset", 0.5), "offset 0.5, not a whole number of bytes"),
        (_set("arrays", "network/input_mean", "offset", 1), "starts at byte 1, not 0 where the previous array ends"),
        (_set("arrays", "network/input_mean", "shape", [10**12]), "lies outside the file"),
        (_set("arrays", "network/input_mean", "shape", [1, 1, 1, 1, 1]), "a shape is up to 4 whole numbers"),
        (_set("arrays", "network/input_mean", "dtype", "object"), "dtypes allowed"),
        (lambda h: h["arrays"].update({f"extra/a{i}": {"dtype": "int32", "shape": [0], "offset": 0} for i in range(300)}),
         "declares 301 arrays|declares 3\\d\\d arrays"),
        (_set("metadata", "windows", "skull", 10000), "windows.skull 10000 \\(skin features of 60003\\) and windows.skull velocity over "
         "20001 frames x 5 landmarks \\(300015 skull features\\) make 360018 network inputs, but its architecture has 378"),
        (_set("metadata", "skull_landmarks", [[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [1.0, 1.0, 1.0], [2.0, 0.0, 1.0], [0.0, 2.0, 3.0]]), "x 6 landmarks \\(378 skull features\\) make 441 network inputs"),
        (_set("metadata", "skull_motion", {"kind": "acceleration", "past": 10**12, "future": 10}), "skull_motion .* needs past and future"),
        (_set("metadata", "skull_motion", {"kind": "acceleration", "past": 30, "future": 10}), "make 678 network inputs, but its architecture has 378"),
        (lambda h: h["metadata"].update(skull_motion={"kind": "velocity", "past": 10, "future": 10}, windows={"target": 10}),
         "a removal model needs windows.skull"),
    ],
    ids=["fps-nan", "fps-string", "fps-zero", "fps-huge", "fps-bool", "window-fraction", "kind", "100k-layers",
         "giant-width", "architecture-mismatch", "samples-fraction", "samples-huge", "landmark-huge-int", "landmark-nan", "point-count", "no-fingerprint", "version-bool",
         "version-3", "fractional-offset", "gap", "huge-shape", "too-many-dims", "object-dtype", "too-many-arrays",
         "window-10000", "landmarks-added", "skull-motion-huge", "skull-motion-inconsistent", "no-skull-window"],
)
def test_crafted_headers_are_refused_before_allocating(tmp_path, edit, message):
    blob = save_model(make_model(), tmp_path / "actor.fdyn").read_bytes()
    path = craft(tmp_path / "crafted.fdyn", blob, edit)
    with pytest.raises(ModelFileError, match=message) as error:
        load_model(path)
    assert str(error.value).startswith(str(path)) or str(path) in str(error.value)
    assert "\n" not in str(error.value)


def test_a_model_whose_frames_cost_more_than_its_size_allows_is_refused(tmp_path, monkeypatch):
    """Consistent sizes can still make one frame expensive (wide windows, many samples): bounded by the file's size."""
    from facedyn.dynamics import modelfile

    path = save_model(make_model(), tmp_path / "actor.fdyn")
    per_frame = modelfile.frame_bytes(load_model(path))
    assert per_frame["per_frame"] == 4 * (12 * (378 + 256 + 3) + 3 * 80 * 3 + 12 * 378 + 5 * 21 * 3)
    assert per_frame["context_frames"] == 21 and per_frame["context"] == 4 * (12 * 378 + 5 * 21 * 3)
    one_frame = per_frame["per_frame"] + 21 * per_frame["context"]
    monkeypatch.setattr(modelfile, "FRAME_BYTES_FLOOR", 0)
    size = path.stat().st_size
    assert one_frame <= 4 * size  # a trained model's frame is cheap next to its file
    small = craft(tmp_path / "small.fdyn", path.read_bytes())
    monkeypatch.setattr(modelfile, "FRAME_BYTES_FLOOR", 0)
    monkeypatch.setattr(modelfile, "_check_sizes", _bounded(modelfile._check_sizes, one_frame // 4 - 1))
    with pytest.raises(ModelFileError, match=r"small.fdyn: applying it would allocate .* MiB for a single frame .* more than 4 times"):
        load_model(small)


def _bounded(check, file_bytes):
    return lambda path, model, _size: check(path, model, file_bytes)


def test_chunks_shrink_to_what_a_model_can_afford(monkeypatch):
    from facedyn.dynamics import modelfile

    model = make_model()
    assert modelfile.affordable_frames(model, 128) == 128
    cost = modelfile.frame_bytes(model)
    monkeypatch.setattr(modelfile, "CHUNK_BYTES", 21 * cost["context"] + 5 * cost["per_frame"] + 1)
    assert modelfile.affordable_frames(model, 128) == 5
    monkeypatch.setattr(modelfile, "CHUNK_BYTES", 0)
    assert modelfile.affordable_frames(model, 128) == 1


def test_headers_that_are_not_model_headers(tmp_path):
    blob = save_model(make_model(), tmp_path / "actor.fdyn").read_bytes()
    cases = {
        "deep.fdyn": b"[" * 100_000,
        "latin.fdyn": b'{"metadata": "\xe9"}',
        "list.fdyn": b"[1, 2]",
    }
    for name, header in cases.items():
        (tmp_path / name).write_bytes(b"FDYNMDL1" + struct.pack("<Q", len(header)) + header)
        with pytest.raises(ModelFileError, match=f"{name} has an unreadable header"):
            load_model(tmp_path / name)
    (tmp_path / "huge.fdyn").write_bytes(b"FDYNMDL1" + struct.pack("<Q", 2**40) + blob[16:])
    with pytest.raises(ModelFileError, match="declares a header of 1099511627776 bytes, more than the 16777216"):
        load_model(tmp_path / "huge.fdyn")
    (tmp_path / "tail.fdyn").write_bytes(blob + b"\0" * 8)
    with pytest.raises(ModelFileError, match="tail.fdyn holds 8 bytes after its last array"):
        load_model(tmp_path / "tail.fdyn")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="FIFOs are POSIX")
def test_only_regular_files_are_read(tmp_path):
    os.mkfifo(tmp_path / "pipe.fdyn")
    with pytest.raises(ModelFileError, match="pipe.fdyn: is not a regular file"):
        load_model(tmp_path / "pipe.fdyn")
    if os.path.exists("/dev/zero"):
        with pytest.raises(ModelFileError, match="/dev/zero: is not a regular file"):
            load_model("/dev/zero")
    with pytest.raises(ModelFileError, match="is a folder"):
        load_model(tmp_path)


def test_version_1_files_load_with_a_warning_and_re_save_as_version_2(tmp_path):
    model = make_model()
    blob = save_model(model, tmp_path / "new.fdyn").read_bytes()

    def as_version_1(header):
        header["metadata"]["version"] = 1
        del header["checksums"]
    old = craft(tmp_path / "old.fdyn", blob, as_version_1, sign=False)
    loaded = load_model(old)
    assert loaded.warnings == [f"{old} is model format version 1, written without checksums, so damage to it cannot be "
                               "detected; re-save it (load and save it with this facedyn) to add them"]
    assert_same_network(loaded, model)
    described = describe_model(old)
    assert described["format_version"] == 1 and described["checksum"] is None and described["warnings"] == loaded.warnings
    resaved = save_model(loaded, tmp_path / "resaved.fdyn")
    assert resaved.read_bytes() == blob and load_model(resaved).warnings == []


def test_describe_model_says_what_inspect_shows(tmp_path):
    model = make_model("removal", removal_spec(615), SkullMotionInput())
    path = save_model(model, tmp_path / "actor.removal")
    header, data = _parts(path.read_bytes())
    described = describe_model(path)
    assert described == {
        "path": str(path), "format_version": 2, "kind": "removal", "network": "F",
        "topology_fingerprint": model.fingerprint, "point_count": 80, "fps": 120.0,
        "windows": {"skull": 10, "skin": 10, "target": 10},
        "skull_features": SkullMotionInput().to_json(), "samples": 12, "landmarks": len(model.face.landmarks),
        "rigid_vertices": 16, "architecture": {"inputs": 678, "hidden": [128, 128], "outputs": 3, "activation": "relu"},
        "parameters": 678 * 128 + 128 + 128 * 128 + 128 + 128 * 3 + 3,
        # float32: 12 samples x (678 inputs + 256 hidden + 3 outputs), 3 mesh arrays of 80 points,
        # the features (12 x 678) and the kernel's B(t) over t-10..t+10 for 5 landmarks
        "bytes_per_frame": 4 * (12 * (678 + 256 + 3) + 3 * 80 * 3 + 12 * 678 + 5 * 21 * 3),
        "training": {"takes": [{"name": "walk", "frames": 300}]}, "validation": {"rms_cm": 0.01},
        "checksum": header["checksums"], "warnings": [], "bytes": path.stat().st_size,
    }
    assert described["checksum"]["arrays"] == hashlib.sha256(
        json.dumps(header["arrays"], sort_keys=True, separators=(",", ":")).encode() + data).hexdigest()


def test_a_nan_frame_rate_never_matches(tmp_path):
    loaded = load_model(save_model(make_model(), tmp_path / "actor.fdyn"))
    with pytest.raises(ModelMismatch, match="runs at nan fps"):
        loaded.check_compatible(fps=float("nan"))


def test_loaded_weights_are_ordinary_float32_parameters_whatever_dtype_the_file_stores(tmp_path):
    """Loading hands the file's arrays to the network without a copy; a crafted float64 or int32 weight still
    becomes a float32 parameter on the CPU that trains, as a copy into a fresh network would have made it."""
    model = make_model()
    blob = save_model(model, tmp_path / "actor.fdyn").read_bytes()
    header, data = _parts(blob)
    entry = header["arrays"]["network/layers.4.weight"]
    start, end = entry["offset"], entry["offset"] + 4 * int(np.prod(entry["shape"]))
    wide = np.frombuffer(data[start:end], "<f4").astype("<f8").tobytes()

    def widen(h):
        h["arrays"]["network/layers.4.weight"]["dtype"] = "float64"
        for name, spec in h["arrays"].items():
            if spec["offset"] > entry["offset"]:
                spec["offset"] += len(wide) - (end - start)
    loaded = load_model(craft(tmp_path / "wide.fdyn", blob, widen, data=data[:start] + wide + data[end:]))
    network = loaded.torch_network()
    tensors = list(network.parameters()) + list(network.buffers())
    assert all(t.dtype == torch.float32 and t.device.type == "cpu" for t in tensors)
    assert all(p.requires_grad for p in network.parameters())
    x = torch.randn(20, 378)
    with torch.no_grad():
        np.testing.assert_array_equal(network(x).numpy(), model.network(x).numpy())
    network(x).sum().backward()
    assert network.layers[0].weight.grad is not None


INSPECT_PROBE = """
import contextlib, io, json, sys
import facedyn.cli
with contextlib.redirect_stdout(io.StringIO()) as out:
    code = facedyn.cli.main(["inspect", "--json", sys.argv[1]])
heavy = sorted({m.split(".")[0] for m in sys.modules} & {"torch", "scipy", "pyopencl", "pxr"})
print(json.dumps({"code": code, "heavy": heavy, "described": json.loads(out.getvalue()) if code == 0 else None}))
"""


def test_inspect_model_reads_the_file_without_torch_or_scipy(tmp_path):
    """`usdfacedyn inspect MODEL` checks the file (checksums, array table, implied sizes) and builds no network:
    torch and SciPy stay unimported (issue 40: inspect MODEL <= 0.5 s), and it shows what describe_model does."""
    import subprocess
    import sys

    path = save_model(make_model(), tmp_path / "actor.removal")
    done = subprocess.run([sys.executable, "-c", INSPECT_PROBE, str(path)], capture_output=True, text=True)
    result = json.loads(done.stdout.strip().splitlines()[-1])
    assert result["code"] == 0 and result["heavy"] == [], done.stderr
    assert result["described"] == json.loads(json.dumps(describe_model(path)))
    blob = bytearray(path.read_bytes())
    blob[-1] ^= 0xFF  # a weight's last byte: inspect still verifies the checksums
    (tmp_path / "damaged.removal").write_bytes(bytes(blob))
    done = subprocess.run([sys.executable, "-m", "facedyn.cli", "inspect", str(tmp_path / "damaged.removal")], capture_output=True, text=True)
    assert done.returncode == 1 and "do not match the checksum" in done.stderr
