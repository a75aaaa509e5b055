"""Issue 39, items 4 and 5: staleness follows content, not paths; a take's root is its own.

A layer is stale exactly when what it was computed from changed: a hand edit of a layer
below is caught, a take folder moved or copied (its source or models left behind) is not
stale, and `layers`, `inspect` and `validate` read one state. A layer goes only into the
root it was read from; a root listing itself, and muting or detaching the capture, are
refused; `layers` on a data layer says which root to use.
"""
import shutil

import numpy as np
import pytest
from pxr import Sdf, Vt

from facedyn.cli import main
from facedyn.errors import UsageError
from facedyn.usd import schema
from facedyn.usd.errors import TakeError
from facedyn.usd.inspect import describe_take
from facedyn.usd.layers import LayerContent, write_layer
from facedyn.usd.outputs import check_output_paths
from facedyn.usd.rootedit import attach, detach, mute
from facedyn.usd.stackstatus import check_take_root, format_layers, stack_status
from facedyn.usd.take import read_take_below
from facedyn.usd.validate import validate_take

from stack_fixtures import FRAMES, TIMING, base_points, build_take, make_capture, write_role_layer

POINTS = "/Performance/Skull/Face.points"


def cli(*argv):
    return main([str(a) for a in argv] + ([] if argv[0] == "layers" else ["-q"]))


def _states(root):
    return {s.asset: s.state for s in stack_status(root)}


def _move_points(layer_path, by=(5.0, 0.0, 0.0)):
    """A hand edit: every point of every frame moved, the layer's metadata untouched."""
    layer = Sdf.Layer.OpenAsAnonymous(str(layer_path))
    for t in layer.ListTimeSamplesForPath(POINTS):
        points = np.asarray(layer.QueryTimeSample(POINTS, t)) + np.float32(by)
        layer.SetTimeSample(POINTS, t, Vt.Vec3fArray.FromNumpy(points.astype(np.float32)))
    layer.Export(str(layer_path))


def _not_ok_in_validate(root):
    """The layers validate reports as stale, missing or fed by nothing (the stack's state findings)."""
    kinds = {"facedyn:Stale", "facedyn:LayerRequires", "facedyn:LayerStack"}
    return {f.file for f in validate_take(root) if f.validator in kinds}


def test_a_hand_edit_of_the_capture_makes_every_layer_above_stale_and_steps_refuse_it(tmp_path, capsys):
    root = build_take(tmp_path)
    assert set(_states(root).values()) == {"ok"}
    _move_points(tmp_path / "capture.usdc")
    status = {s.asset: s for s in stack_status(root)}
    assert status["./stabilized.usdc"].reason.startswith("its input ./capture.usdc changed since (content ")
    assert [a for a, s in status.items() if s.state != "ok"] == ["./take.preview.usdc", "./synthesized.hop.usdc",
                                                                   "./quasistatic.usdc", "./stabilized.usdc"]
    assert any(f.validator == "facedyn:Stale" and "./stabilized.usdc: stale" in f.message for f in validate_take(root))
    # A step reading the stale stabilized layer stops before any work, naming it and what to re-run.
    capsys.readouterr()
    assert cli("preview", root, "-o", tmp_path / "again.preview.usdc", "--attach", root) == 1
    err = capsys.readouterr().err
    assert "the layer ./synthesized.hop.usdc it would read is stale" in err and "re-run `usdfacedyn synthesize`" in err
    assert not (tmp_path / "again.preview.usdc").exists()
    # Recomputing bottom up makes each layer fresh again.
    for name, role_name in (("stabilized.usdc", "stabilized"), ("quasistatic.usdc", "quasistatic"),
                            ("synthesized.hop.usdc", "synthesized"), ("take.preview.usdc", "preview")):
        attach(root, write_role_layer(root, name, role_name))
    assert set(_states(root).values()) == {"ok"}


def test_an_edit_that_restores_the_bytes_is_no_change(tmp_path):
    root = build_take(tmp_path)
    before = (tmp_path / "stabilized.usdc").read_bytes()
    _move_points(tmp_path / "stabilized.usdc")
    assert _states(root)["./quasistatic.usdc"] == "stale"
    (tmp_path / "stabilized.usdc").write_bytes(before)  # same content, newer modification time
    assert set(_states(root).values()) == {"ok"}


def test_a_take_folder_moved_or_copied_stays_current_with_its_source_and_models_left_behind(tmp_path):
    take = tmp_path / "studio" / "take"
    take.mkdir(parents=True)
    root, _ = make_capture(take)
    shutil.move(take / "source.txt", tmp_path / "studio" / "source.txt")  # the source outside the take folder
    attach(root, write_role_layer(root, "stabilized.usdc", "stabilized"))
    models = tmp_path / "studio" / "models"
    models.mkdir()
    (models / "removal.model").write_bytes(b"weights v1")
    attach(root, write_role_layer(root, "quasistatic.usdc", "quasistatic", extra_inputs=[models / "removal.model"]))
    assert set(_states(root).values()) == {"ok"}
    copy = tmp_path / "elsewhere" / "deeper" / "take"
    shutil.copytree(take, copy)
    moved = tmp_path / "moved"
    shutil.move(take, moved)
    (tmp_path / "studio" / "source.txt").unlink()  # the import source deleted
    for where in (copy, moved):
        status = {s.asset: s for s in stack_status(where / "take.usda")}
        assert {a: s.state for a, s in status.items()} == {"./quasistatic.usdc": "ok", "./stabilized.usdc": "ok", "./capture.usdc": "ok"}
        # The model is not found from the copy: its content is not known to have changed, so it is unchecked, not stale.
        assert status["./quasistatic.usdc"].unchecked.startswith("its input ../models/removal.model is not found from here")
        assert not status["./capture.usdc"].unchecked  # a capture's source is its history, never checked
        assert "unchecked: its input ../models/removal.model" in format_layers(list(status.values()))
    # Where the model is found again and changed, the layer is stale; recomputing clears it.
    (tmp_path / "elsewhere" / "deeper" / "models").mkdir()
    (tmp_path / "elsewhere" / "deeper" / "models" / "removal.model").write_bytes(b"weights v2")
    assert _states(copy / "take.usda")["./quasistatic.usdc"] == "stale"
    attach(copy / "take.usda", write_role_layer(copy / "take.usda", "quasistatic.usdc", "quasistatic",
                                                extra_inputs=[tmp_path / "elsewhere" / "deeper" / "models" / "removal.model"]))
    assert set(_states(copy / "take.usda").values()) == {"ok"}


def test_a_layer_written_as_value_clips_is_identified_by_its_clips_too(tmp_path):
    root, _ = make_capture(tmp_path)
    _, source = read_take_below(root, "stabilized")
    content = LayerContent(frames=FRAMES, points=base_points() + 1.0, face=schema.FaceAttributes(role="stabilized"))
    provenance = schema.Provenance("stabilize", "test 1", {}, (FRAMES[0], FRAMES[-1]), list(source.inputs), role="stabilized")
    stabilized = write_layer(tmp_path / "stabilized.usdc", content, TIMING, provenance, chunks=[content], clip_threshold=4)
    attach(root, stabilized)
    attach(root, write_role_layer(root, "quasistatic.usdc", "quasistatic"))
    assert set(_states(root).values()) == {"ok"}
    clip = sorted(tmp_path.glob("stabilized.*.clips/*.usdc"))[0]
    _move_points(clip)
    assert (tmp_path / "stabilized.usdc").is_file() and _states(root)["./quasistatic.usdc"] == "stale"


def test_layers_written_before_content_ids_are_still_checked_by_their_runs(tmp_path):
    root = build_take(tmp_path)
    runs = {n: dict(Sdf.Layer.OpenAsAnonymous(str(tmp_path / n)).customLayerData)["facedyn"]["run"]
            for n in ("stabilized.usdc", "capture.usdc")}
    old = Sdf.Layer.OpenAsAnonymous(str(tmp_path / "quasistatic.usdc"))
    data = dict(old.customLayerData)
    facedyn = dict(data["facedyn"])
    for key in ("inputIdentity", "inputKinds"):
        del facedyn[key]
    facedyn["inputRuns"] = Vt.StringArray([runs["stabilized.usdc"], runs["capture.usdc"]])  # what older layers recorded
    data["facedyn"] = facedyn
    old.customLayerData = data
    old.Export(str(tmp_path / "quasistatic.usdc"))
    status = {s.asset: s for s in stack_status(root)}["./quasistatic.usdc"]
    assert status.state == "ok" and status.unchecked.startswith("written before inputs were identified by content")
    attach(root, write_role_layer(root, "stabilized.usdc", "stabilized", params={"iterations": 3}))  # a re-run below it
    assert _states(root)["./quasistatic.usdc"] == "stale"


def test_layers_and_validate_agree_after_muting_a_layer_others_are_computed_from(tmp_path, capsys):
    root = build_take(tmp_path)
    mute(root, "./quasistatic.usdc")
    status = {s.asset: s for s in stack_status(root)}
    synthesized = status["./synthesized.hop.usdc"]
    assert synthesized.state == "stale" and synthesized.needs == "quasistatic"
    assert synthesized.reason == "its input ./quasistatic.usdc is no longer below it (muted, detached or gone)"
    not_ok = {str(s.path) for s in status.values() if s.state not in ("ok", "muted")}
    assert not_ok == _not_ok_in_validate(root) == {str(tmp_path / "synthesized.hop.usdc"), str(tmp_path / "take.preview.usdc")}
    layers = {layer["layer"]: layer for layer in describe_take(root)["layers"]}
    assert layers[str(tmp_path / "synthesized.hop.usdc")]["stale"]
    capsys.readouterr()
    assert cli("layers", root) == 0
    listing = capsys.readouterr().out
    assert "./synthesized.hop.usdc" in listing and "a synthesized layer needs a quasistatic layer below it" in listing
    assert listing.splitlines()[2].split()[-1] == "stale"


def test_attach_goes_only_to_the_root_the_step_read(tmp_path, capsys):
    a, b = tmp_path / "A", tmp_path / "B"
    a.mkdir()
    b.mkdir()
    root_a, _ = make_capture(a)
    root_b, _ = make_capture(b)
    with pytest.raises(UsageError, match="a layer goes only into the root whose layers it was computed from"):
        check_output_paths(a / "stabilized.usdc", [root_a], attach=root_b, role="stabilized")
    before = root_b.read_bytes()
    assert cli("stabilize", root_a, "-o", a / "stabilized.usdc", "--attach", root_b) == 2
    assert "--attach " in capsys.readouterr().err
    assert root_b.read_bytes() == before and not (a / "stabilized.usdc").exists()


def test_a_root_listing_itself_is_refused_until_that_entry_is_detached(tmp_path, capfd):
    root = build_take(tmp_path)
    layer = Sdf.Layer.OpenAsAnonymous(str(root))
    layer.subLayerPaths.append("./take.usda")
    layer.Export(str(root))
    capfd.readouterr()
    assert cli("stabilize", root, "-o", tmp_path / "s.usdc", "--attach", root) == 2
    assert "lists itself among its subLayers (./take.usda)" in capfd.readouterr().err
    assert cli("layers", root) == 2
    assert cli("layers", root, "--mute", "./quasistatic.usdc") == 2
    capfd.readouterr()
    assert main(["inspect", str(root)]) == 2  # it showed the rest of the stack and exited 0, with only USD's warning
    err = capfd.readouterr().err
    assert "lists itself among its subLayers (./take.usda)" in err and len(err.strip().splitlines()) == 1, err
    assert main(["validate", str(root)]) == 1  # a finding of its report, without USD's own warning (C++, on fd 2)
    out, err = capfd.readouterr()
    assert "ERROR facedyn:LayerStack" in out and "lists itself (./take.usda)" in out and err == "", err
    assert cli("layers", root, "--detach", "./take.usda") == 0
    assert "./take.usda" not in Sdf.Layer.OpenAsAnonymous(str(root)).subLayerPaths
    assert set(_states(root).values()) == {"ok"}


def test_the_capture_can_be_neither_muted_nor_detached(tmp_path, capsys):
    root = build_take(tmp_path)
    before = root.read_bytes()
    for edit in (mute, detach):
        with pytest.raises(UsageError, match="is the take's captured layer"):
            edit(root, "./capture.usdc")
    assert cli("layers", root, "--mute", "capture.usdc") == 2
    assert cli("layers", root, "--detach", tmp_path / "capture.usdc") == 2
    assert root.read_bytes() == before


def test_layers_on_a_data_layer_names_its_root(tmp_path, capsys):
    root = build_take(tmp_path)
    with pytest.raises(TakeError, match=r"capture.usdc: not a take root, it lists no layers; its take root is .*take.usda"):
        check_take_root(tmp_path / "capture.usdc")
    alone = tmp_path / "alone"
    alone.mkdir()
    shutil.copy(tmp_path / "capture.usdc", alone / "capture.usdc")
    with pytest.raises(TakeError, match="not a take root, it lists no layers; give the take's root"):
        check_take_root(alone / "capture.usdc")
    capsys.readouterr()
    assert cli("layers", tmp_path / "capture.usdc") == 1
    assert "its take root is" in capsys.readouterr().err
    check_take_root(root)


def test_a_simulated_takes_truth_stack_reads_as_current(tmp_path):
    from facedyn.sim.corpus import TakeSpec, simulate_take
    from facedyn.sim.default_face import default_face
    from facedyn.usd.corpus_files import write_simulated_take

    rig = default_face(8)
    write_simulated_take(tmp_path, simulate_take(rig, TakeSpec("walk", "walk", "smile", duration_s=0.3, seed=1)), rig)
    assert [s.state for s in stack_status(tmp_path / "truth.usda")] == ["ok", "ok", "ok"]


def test_a_model_named_by_a_parameter_is_recorded_relative_to_the_layer_and_once_as_an_input(tmp_path):
    from facedyn.processors import registry
    from facedyn.processors.base import Request
    from facedyn.processors.runner import _recorded_parameters, _with_files

    take, models = tmp_path / "take", tmp_path / "models"
    take.mkdir()
    models.mkdir()
    (models / "f.removal").write_bytes(b"weights")
    remove = registry.load("remove")
    request = Request(inputs=[take / "take.usda"], output=take / "quasistatic.usdc",
                      params=remove.resolve_params({"model": models / "f.removal"}), attach=take / "take.usda")
    parameters, files = _recorded_parameters(remove, request, request.attach)
    assert parameters["model"] == "../models/f.removal" and files == [(models / "f.removal").resolve()]
    read = [str((take / "capture.usdc").resolve()), str((models / "f.removal").resolve())]  # remove's own inputs name it already
    assert _with_files(read, files, request.output) == read
    assert _with_files(["DefaultFace"], files, request.output) == ["DefaultFace", (models / "f.removal").resolve()]
    # The layer being written is never its own input (a take's own root read through another parameter)
    assert _with_files(read + [str(request.output)], files + [request.output.resolve()], request.output) == read
