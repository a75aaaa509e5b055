"""Run identity, output paths that cannot clash, staleness and coverage in validate/inspect."""
import hashlib
import json
import shutil

import pytest
from pxr import Sdf, Usd

from facedyn.errors import UsageError
from facedyn.usd import schema
from facedyn.usd.inspect import describe_take, format_description
from facedyn.usd.outputs import check_output_paths
from facedyn.usd.rootedit import attach, mute
from facedyn.usd.stackstatus import format_layers, stack_status
from facedyn.usd.validate import validate_take

from stack_fixtures import FRAMES, build_take, make_capture, sublayers, write_role_layer


def _meta(path):
    layer = Sdf.Layer.OpenAsAnonymous(str(path))
    return dict(dict(layer.customLayerData)["facedyn"])


def _facedyn_findings(root):
    return [(f.severity, f.validator, f.message) for f in validate_take(root) if f.validator.startswith("facedyn:")]


def test_every_layer_records_its_role_and_a_run_id_computed_from_its_inputs(tmp_path):
    root = build_take(tmp_path)
    quasistatic, stabilized = _meta(tmp_path / "quasistatic.usdc"), _meta(tmp_path / "stabilized.usdc")
    capture = _meta(tmp_path / "capture.usdc")
    assert quasistatic["processor"] == "remove" and quasistatic["role"] == "quasistatic"
    assert list(quasistatic["inputs"]) == ["./stabilized.usdc", "./capture.usdc"]
    # Every input is identified by its content: a sha256 of its bytes, the layers read as much as any other file.
    contents = [hashlib.sha256((tmp_path / n).read_bytes()).hexdigest()[:16] for n in ("stabilized.usdc", "capture.usdc")]
    assert list(quasistatic["inputRuns"]) == contents and list(quasistatic["inputKinds"]) == ["layer", "layer"]
    assert quasistatic["inputIdentity"] == "content" and stabilized["run"] not in contents
    # The run id is the sha256 of the canonical JSON of what the run was (DESIGN: same inputs, same id).
    canonical = json.dumps({"processor": "remove", "version": "test 1", "parameters": {}, "frameRange": [1001.0, 1010.0],
                            "inputs": contents}, sort_keys=True, separators=(",", ":"))
    assert quasistatic["run"] == hashlib.sha256(canonical.encode()).hexdigest()[:16]
    assert list(capture["inputRuns"]) == [hashlib.sha256(b"the studio's mesh cache").hexdigest()[:16]]
    assert list(capture["inputKinds"]) == ["file"]
    stage = Usd.Stage.Open(str(root))
    face = stage.GetPrimAtPath("/Performance/Skull/Face")
    runs = {run["processor"]: run for run in schema.read_provenance(face)}
    assert runs["remove"]["run"] == quasistatic["run"] and runs["remove"]["role"] == "quasistatic"
    assert runs["remove"]["inputRuns"] == list(quasistatic["inputRuns"])


def test_same_inputs_give_the_same_bytes_wherever_the_take_lies(tmp_path):
    first, second = tmp_path / "a", tmp_path / "b" / "deeper"
    first.mkdir()
    second.mkdir(parents=True)
    build_take(first)
    build_take(second)
    for name in ("capture.usdc", "stabilized.usdc", "quasistatic.usdc", "synthesized.hop.usdc", "take.preview.usdc", "take.usda"):
        assert (first / name).read_bytes() == (second / name).read_bytes(), name
    # A different parameter is a different run, and so is everything computed from it.
    before = _meta(first / "stabilized.usdc")["run"]
    write_role_layer(first / "take.usda", "stabilized.usdc", "stabilized", params={"iterations": 24})
    assert _meta(first / "stabilized.usdc")["run"] != before


CLASHES = [
    # (output, inputs, attach, root, role, message)
    ("capture.usdc", ["take.usda"], "take.usda", None, "stabilized", "is its captured layer of .*take.usda"),
    ("stabilized.usdc", ["take.usda"], "take.usda", None, "quasistatic", "is its stabilized layer of .*take.usda"),
    ("take.usda", ["take.usda"], None, None, "stabilized", "would overwrite the input"),
    ("s.usdc", ["take.usda"], "s.usdc", None, "stabilized", "also the --attach root; a layer cannot list itself"),
    ("sub/take.usda", ["sub/src.usdc"], None, "sub/take.usda", "captured", "also the --root root"),
    ("cap.usdc", ["src.usdc"], None, "src.usdc", "captured", "--root names a data layer of the input"),
    ("s.usdc", ["take.usda"], "capture.usdc", None, "stabilized", "--attach names a data layer of the input"),
    ("link.usdc", ["take.usda"], "take.usda", None, "stabilized", "is its captured layer"),  # a symlink to capture.usdc
    ("quasistatic.usdc", ["take.usda"], "take.usda", None, None, "is its quasistatic layer"),
]


@pytest.mark.parametrize("output, inputs, attach_to, root, role, message", CLASHES)
def test_outputs_that_would_clash_are_usage_errors(tmp_path, output, inputs, attach_to, root, role, message):
    build_take(tmp_path)
    (tmp_path / "sub").mkdir()
    for src in (tmp_path / "src.usdc", tmp_path / "sub" / "src.usdc"):
        shutil.copy(tmp_path / "capture.usdc", src)
    (tmp_path / "link.usdc").symlink_to(tmp_path / "capture.usdc")
    at = (lambda p: None if p is None else tmp_path / p)
    with pytest.raises(UsageError, match=message):
        check_output_paths(tmp_path / output, [tmp_path / i for i in inputs], attach=at(attach_to), root=at(root), role=role)


def test_outputs_that_replace_their_own_roles_layer_are_fine(tmp_path):
    root = build_take(tmp_path)
    check_output_paths(tmp_path / "stabilized.usdc", [root], attach=root, role="stabilized")
    check_output_paths(tmp_path / "synthesized.hop.usdc", [root], attach=root, role="synthesized")
    check_output_paths(tmp_path / "capture.usdc", [tmp_path / "src.usda"], root=root, role="captured")  # a re-import
    check_output_paths(tmp_path / "synthesized.walk.usdc", [root], attach=root, role="synthesized")
    mute(root, "./quasistatic.usdc")  # a layer muted on disk still belongs to the take
    with pytest.raises(UsageError, match="is its quasistatic layer"):
        check_output_paths(tmp_path / "quasistatic.usdc", [root], attach=root, role="stabilized")


def test_a_changed_model_makes_its_layer_stale_and_a_vanished_one_unchecked(tmp_path):
    root, _ = make_capture(tmp_path)
    attach(root, write_role_layer(root, "stabilized.usdc", "stabilized"))
    model = tmp_path / "removal.model"
    model.write_bytes(b"weights v1")
    attach(root, write_role_layer(root, "quasistatic.usdc", "quasistatic", extra_inputs=[model]))
    assert not any(s.stale for s in stack_status(root))
    model.write_bytes(b"weights v2, retrained")
    status = {s.asset: s for s in stack_status(root)}
    assert status["./quasistatic.usdc"].reason == "its input ./removal.model changed since it was computed"
    # A model that cannot be found (a take folder copied without it) says nothing about its content: unchecked, not stale.
    model.unlink()
    status = {s.asset: s for s in stack_status(root)}["./quasistatic.usdc"]
    assert status.state == "ok" and status.unchecked == "its input ./removal.model is not found from here; its content was not checked"
    assert ("warning", "facedyn:Unchecked", f"./quasistatic.usdc: {status.unchecked}") in _facedyn_findings(root)


def test_reordered_variants_make_the_overlay_above_them_stale(tmp_path):
    from facedyn.usd.rootedit import move

    root, _ = make_capture(tmp_path)
    for name, role_name in (("stabilized.usdc", "stabilized"), ("quasistatic.usdc", "quasistatic"),
                            ("synthesized.hop.usdc", "synthesized"), ("synthesized.walk.usdc", "synthesized"),
                            ("take.preview.usdc", "preview")):
        attach(root, write_role_layer(root, name, role_name))
    move(root, "./synthesized.hop.usdc", above="./synthesized.walk.usdc")
    status = {s.asset: s for s in stack_status(root)}
    assert status["./take.preview.usdc"].reason == "the layers below it were reordered since it was computed"
    assert not status["./synthesized.walk.usdc"].stale  # variants do not read each other


def test_validate_reports_the_stack_problems_of_issue_15(tmp_path):
    root = build_take(tmp_path)
    assert _facedyn_findings(root) == []
    attach(root, write_role_layer(root, "stabilized.usdc", "stabilized", params={"method": "icp"}))  # a re-run
    findings = _facedyn_findings(root)
    assert [f[:2] for f in findings] == [("warning", "facedyn:Stale")] * 3
    assert "./quasistatic.usdc: stale, its input ./stabilized.usdc changed since" in findings[2][2]
    # Hand edits a TD might make: a partial layer, a layer out of order, one listed twice, a root listing itself.
    write_role_layer(root, "synthesized.part.usdc", "synthesized", frames=FRAMES[:6])
    layer = Sdf.Layer.FindOrOpen(str(root))
    layer.subLayerPaths = ["./synthesized.part.usdc", "./stabilized.usdc", "./quasistatic.usdc", "./capture.usdc", "capture.usdc", "./take.usda"]
    layer.Save()
    errors = {(f[1], f[2].split(": ", 1)[-1]) for f in _facedyn_findings(root) if f[0] == "error"}
    assert ("facedyn:FrameCoverage", "covers frames 1001..1006, the take 1001..1010; the frames it lacks hold its nearest value") in errors
    assert any(v == "facedyn:LayerOrder" and m.startswith("./stabilized.usdc (stabilized) sits above ./quasistatic.usdc (quasistatic)") for v, m in errors)
    assert ("facedyn:LayerStack", "lists capture.usdc twice (also as ./capture.usdc)") in errors
    assert ("facedyn:LayerStack", "lists itself (./take.usda) among its subLayers") in errors


def test_inspect_and_the_layer_listing_show_role_and_staleness(tmp_path):
    root = build_take(tmp_path)
    attach(root, write_role_layer(root, "stabilized.v2.usdc", "stabilized", value=1.5))
    mute(root, "./take.preview.usdc")
    description = describe_take(root)
    layers = {l["layer"].rsplit("/", 1)[-1]: l for l in description["layers"]}
    assert layers["quasistatic.usdc"]["role"] == "quasistatic" and layers["quasistatic.usdc"]["stale"]
    assert "stabilized.v2.usdc lies below it" in layers["quasistatic.usdc"]["staleReason"]
    assert not layers["stabilized.v2.usdc"]["stale"] and description["mutedOnDisk"] == ["./take.preview.usdc"]
    text = format_description(description)
    assert "STALE: ./stabilized.v2.usdc lies below it" in text and "muted on disk: ./take.preview.usdc" in text
    listing = format_layers(stack_status(root)).splitlines()
    assert listing[0].split() == ["./synthesized.hop.usdc", "synthesized", "synthesize", "1001..1010", "stale"]
    assert listing[-1].split() == ["./take.preview.usdc", "preview", "preview", "1001..1010", "muted"]
    assert sublayers(root)[0] == "./synthesized.hop.usdc"


def test_checking_what_a_step_reads_hashes_nothing_above_it(tmp_path, monkeypatch):
    """A step checks the layers it reads; its own old output and what was computed from it are not its inputs
    (on a 1,000-frame ICT take, hashing them cost remove a third of a second)."""
    from facedyn.usd import runs
    from facedyn.usd.stackstatus import stale_below

    root = build_take(tmp_path)
    hashed = []
    digest = runs._file_digest
    monkeypatch.setattr(runs, "_file_digest", lambda path: hashed.append(path.name) or digest(path))
    assert stale_below(root, "quasistatic") == []
    assert "capture.usdc" in hashed  # what the stabilized layer was computed from
    assert not {"quasistatic.usdc", "synthesized.hop.usdc", "take.preview.usdc"} & set(hashed)
