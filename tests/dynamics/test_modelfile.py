"""Model files: round trip, refusing foreign files and pickles, mismatch errors."""
import json
import pickle
import struct

import numpy as np
import pytest
import torch
from synthetic_face import curved_sheet, top_rows

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.modelfile import DynamicsModel, ModelFileError, ModelMismatch, load_model, read_model_file, save_model
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


def test_round_trip(tmp_path):
    model = make_model()
    path = save_model(model, tmp_path / "actor.fdyn")
    loaded = load_model(path, topology=model.face.topology, fps=120.0)
    assert loaded.kind == "removal" and loaded.fps == 120.0 and loaded.windows == model.windows
    assert loaded.info == model.info and loaded.fingerprint == model.fingerprint
    np.testing.assert_array_equal(loaded.face.samples, model.face.samples)
    np.testing.assert_allclose(loaded.face.landmarks, model.face.landmarks)
    np.testing.assert_array_equal(loaded.face.rigid_vertices, model.face.rigid_vertices)
    x = torch.randn(50, 378)
    with torch.no_grad():
        np.testing.assert_array_equal(loaded.network(x).numpy(), model.network(x).numpy())
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
    model = make_model("synthesis", NetworkSpec(315 + 2 * samples, SYNTHESIS_HIDDEN, 3 * samples), SkullMotionInput("velocity", 10, 10))
    blob = save_model(model, tmp_path / "new.fdyn").read_bytes()
    (length,) = struct.unpack("<Q", blob[8:16])
    header = json.loads(blob[16:16 + length])
    del header["metadata"]["skull_motion"]
    header["metadata"]["windows"] = {"skull": 7, "stretch_smoothing": 10}
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
    with pytest.raises(ModelMismatch, match="trained at 120 fps.*runs at 96 fps"):
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
