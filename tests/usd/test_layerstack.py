"""The layer stack: reading below a role, placing layers by role, locking, layer commands."""
import importlib.util
import multiprocessing
import hashlib
import os
import stat
import textwrap

import numpy as np
import pytest
from pxr import Sdf, Usd

from facedyn.errors import UsageError
from facedyn.performance import roles
from facedyn.usd import layerstack, rootedit
from facedyn.usd.plugin import plugin_root
from facedyn.usd.errors import TakeError
from facedyn.usd.rootedit import attach, attach_written_layer, detach, move, mute, unmute
from facedyn.usd.stackstatus import covers_take, stack_status
from facedyn.usd.take import read_take, read_take_below

from stack_fixtures import FRAMES, OFFSET, base_points, build_take, make_capture, sublayers, write_role_layer

FULL = ["./take.preview.usdc", "./synthesized.hop.usdc", "./quasistatic.usdc", "./stabilized.usdc", "./capture.usdc"]


def _shows(perf, role_name):
    np.testing.assert_allclose(perf.points, base_points() + OFFSET[role_name], atol=1e-6)


def test_layers_are_placed_by_role_whatever_order_they_come_in(tmp_path):
    root, _ = make_capture(tmp_path)
    attach(root, write_role_layer(root, "stabilized.usdc", "stabilized"))
    preview = write_role_layer(root, "take.preview.usdc", "preview")
    quasistatic = write_role_layer(root, "quasistatic.usdc", "quasistatic")
    attach(root, preview)  # the role recorded in the layer places it
    attach(root, quasistatic)
    assert sublayers(root) == ["./take.preview.usdc", "./quasistatic.usdc", "./stabilized.usdc", "./capture.usdc"]
    hop = write_role_layer(root, "synthesized.hop.usdc", "synthesized")
    walk = write_role_layer(root, "synthesized.walk.usdc", "synthesized", value=3.5)
    retargeted = write_role_layer(root, "retargeted.usdc", "retargeted")
    for layer in (hop, walk, retargeted):
        attach(root, layer)
    # Variants: the newest is the strongest of its rank, never above the heat map.
    assert sublayers(root)[:4] == ["./take.preview.usdc", "./retargeted.usdc", "./synthesized.walk.usdc", "./synthesized.hop.usdc"]
    # Re-attaching an existing variant keeps its place.
    attach(root, hop)
    assert sublayers(root)[3] == "./synthesized.hop.usdc"


def test_reading_below_a_role_ignores_everything_at_or_above_it(tmp_path):
    root = build_take(tmp_path)
    assert sublayers(root) == FULL
    for role_name, shows in (("stabilized", "captured"), ("quasistatic", "stabilized"), ("synthesized", "quasistatic"),
                             ("preview", "synthesized")):
        perf, source = read_take_below(root, role_name)
        _shows(perf, shows)
        assert perf.frames[0] == 1001 and source.path == root
    perf, source = read_take_below(root, "quasistatic")
    assert perf.role == "stabilized"  # remove never sees the synthesized layer on top
    assert [os.path.basename(i.path) for i in source.inputs] == ["stabilized.usdc", "capture.usdc"]
    contents = [hashlib.sha256((tmp_path / n).read_bytes()).hexdigest()[:16] for n in ("stabilized.usdc", "capture.usdc")]
    assert [i.run for i in source.inputs] == contents  # each layer read is identified by its bytes
    _shows(read_take(root)[0], "synthesized")  # the composed take is untouched


def test_reading_below_needs_what_the_role_is_computed_from(tmp_path):
    root, _ = make_capture(tmp_path)
    with pytest.raises(TakeError, match="quasistatic layer is computed from a stabilized layer.*usdfacedyn stabilize"):
        read_take_below(root, "quasistatic")
    with pytest.raises(TakeError, match="needs|computed from a quasistatic"):
        read_take_below(root, "synthesized")
    with pytest.raises(TakeError, match="unknown role 'sculpted'"):
        read_take_below(root, "sculpted")


def test_rerun_replaces_its_layer_in_place_and_marks_the_layers_above_stale(tmp_path):
    root = build_take(tmp_path)
    again = write_role_layer(root, "stabilized.v2.usdc", "stabilized", value=1.25, params={"iterations": 24})
    report = attach(root, again, "stabilized")
    assert sublayers(root) == FULL[:3] + ["./stabilized.v2.usdc", "./capture.usdc"]
    assert report.replaced == ["./stabilized.usdc"] and report.role == "stabilized"
    assert report.stale == FULL[:3]  # all computed over the old solve
    status = {s.asset: s for s in stack_status(root)}
    assert "stabilized.v2.usdc lies below it" in status["./quasistatic.usdc"].reason
    assert not status["./stabilized.v2.usdc"].stale and not status["./capture.usdc"].stale
    # The layers above it still show: the re-run did not move to the top.
    _shows(read_take(root)[0], "synthesized")


def test_rerun_under_the_same_name_names_the_changed_input(tmp_path):
    root = build_take(tmp_path)
    attach(root, write_role_layer(root, "stabilized.usdc", "stabilized", value=1.5, params={"iterations": 3}))
    assert sublayers(root) == FULL
    status = {s.asset: s for s in stack_status(root)}
    assert status["./quasistatic.usdc"].reason.startswith("its input ./stabilized.usdc changed since (content ")
    # Recomputing the layers above from the new solve makes them fresh again, one by one.
    attach(root, write_role_layer(root, "quasistatic.usdc", "quasistatic"))
    status = {s.asset: s for s in stack_status(root)}
    assert not status["./quasistatic.usdc"].stale and status["./synthesized.hop.usdc"].stale


def test_frames_keep_the_capture_numbering_and_partial_layers_are_refused(tmp_path):
    root = build_take(tmp_path)
    assert covers_take(root, (1001, 1010)) and covers_take(Usd.Stage.Open(str(root)), (1000, 1012))
    assert not covers_take(root, (1001, 1005))
    partial = write_role_layer(root, "synthesized.part.usdc", "synthesized", frames=FRAMES[:5])
    before = sublayers(root)
    with pytest.raises(TakeError, match=r"covers frames 1001:1005 but the take .* covers 1001:1010.*without --frames"):
        attach(root, partial)
    assert sublayers(root) == before
    perf, _ = read_take_below(root, "preview", frames=(1003, 1004))
    np.testing.assert_array_equal(perf.frames, [1003, 1004])


def test_a_third_party_role_is_placed_read_and_muted_like_a_builtin_one(tmp_path, monkeypatch):
    plugin = tmp_path / "site"
    (plugin / "sculpt_roles-1.0.dist-info").mkdir(parents=True)
    (plugin / "sculpt_roles-1.0.dist-info" / "METADATA").write_text("Metadata-Version: 2.1\nName: sculpt-roles\nVersion: 1.0\n")
    (plugin / "sculpt_roles-1.0.dist-info" / "entry_points.txt").write_text("[facedyn.roles]\nsculpted = sculpt_roles:SCULPTED\n")
    (plugin / "sculpt_roles.py").write_text(textwrap.dedent("""
        from facedyn.performance import Role
        SCULPTED = Role("sculpted", 25, "sculpted layers", reads="quasistatic")
    """))
    monkeypatch.syspath_prepend(str(plugin))
    assert roles()["sculpted"].rank == 25
    take = tmp_path / "take"
    take.mkdir()
    root = build_take(take)
    sculpt = write_role_layer(root, "sculpt.usdc", "sculpted", value=2.5, processor="sculpt")
    attach(root, sculpt)
    assert sublayers(root) == FULL[:2] + ["./sculpt.usdc"] + FULL[2:]
    np.testing.assert_allclose(read_take_below(root, "synthesized")[0].points, base_points() + 2.5, atol=1e-6)
    _shows(read_take_below(root, "sculpted")[0], "quasistatic")
    stage = Usd.Stage.Open(str(root))
    assert layerstack.toggle(stage, {"sculpted"}) is True
    assert [os.path.basename(i) for i in stage.GetMutedLayers()] == ["sculpt.usdc"]
    spec = importlib.util.spec_from_file_location("menu_under_test", plugin_root() / "facedynUsdview" / "__init__.py")
    menu = importlib.util.module_from_spec(spec)  # a private copy: the shared module keeps the built-in menu
    spec.loader.exec_module(menu)
    assert ("toggle_sculpted", "Toggle sculpted layers", frozenset({"sculpted"})) in menu.COMMANDS


def test_a_layer_of_unknown_role_above_the_cut_is_muted_too(tmp_path):
    root = build_take(tmp_path)
    foreign = tmp_path / "fix.usda"
    layer = Sdf.Layer.CreateNew(str(foreign))
    layer.customLayerData = {"facedyn": {"processor": "sculpt", "role": "sculpted", "run": "0"}}
    over = Sdf.CreatePrimInLayer(layer, "/Performance/Skull/Face")
    over.specifier = Sdf.SpecifierOver
    layer.Save()
    edited = Sdf.Layer.FindOrOpen(str(root))
    edited.subLayerPaths.insert(0, "./fix.usda")
    edited.Save()
    perf, source = read_take_below(root, "quasistatic")
    _shows(perf, "stabilized")
    assert "fix.usda" not in {os.path.basename(i.path) for i in source.inputs}


def test_attach_creates_a_root_and_a_reimport_replaces_the_capture(tmp_path):
    root, capture = make_capture(tmp_path)
    assert sublayers(root) == ["./capture.usdc"]
    attach(root, write_role_layer(root, "stabilized.usdc", "stabilized"))
    (tmp_path / "sub").mkdir()
    other = tmp_path / "sub" / "capture2.usdc"
    other.write_bytes(capture.read_bytes())
    report = attach(root, other, "captured")
    assert sublayers(root) == ["./stabilized.usdc", "./sub/capture2.usdc"] and report.replaced == ["./capture.usdc"]
    with pytest.raises(TakeError, match="no such take root"):
        attach(tmp_path / "missing.usda", other)
    with pytest.raises(UsageError, match="cannot list itself"):
        attach(root, root, "stabilized")


@pytest.mark.parametrize("damage", ["missing", "malformed", "read-only", "partial"])
def test_a_failed_attach_leaves_no_new_layer_behind(tmp_path, damage):
    root = build_take(tmp_path)
    before = root.read_bytes()
    output = tmp_path / "synthesized.new.usdc"
    frames = FRAMES
    if damage == "missing":
        root = tmp_path / "gone.usda"
    elif damage == "malformed":
        root.write_text("#usda 1.0\n( subLayers = [ @oops\n")
        before = root.read_bytes()
    elif damage == "read-only":
        root.chmod(0o444)
    else:
        frames = FRAMES[2:]
    content = {}

    def write():
        content["path"] = write_role_layer(tmp_path / "take.usda", output.name, "synthesized", frames=frames)

    with pytest.raises(TakeError):
        attach_written_layer(root, output, "synthesized", write)
    assert not output.exists()
    if root.exists():
        assert root.read_bytes() == before
    assert ("path" in content) == (damage == "partial")  # a root that cannot be edited is refused before the work


def test_a_failed_attach_keeps_a_layer_that_was_there_before(tmp_path):
    root = build_take(tmp_path)
    existing = tmp_path / "quasistatic.usdc"

    def write():
        write_role_layer(root, existing.name, "quasistatic", frames=FRAMES[:4])

    with pytest.raises(TakeError, match="covers frames"):
        attach_written_layer(root, existing, "quasistatic", write)
    assert existing.exists()


@pytest.mark.slow  # fifty processes attach to one take at once
def test_fifty_concurrent_attaches_lose_nothing(tmp_path):
    root = build_take(tmp_path)
    variants = [write_role_layer(root, f"synthesized.v{k:02d}.usdc", "synthesized", value=3 + k / 100) for k in range(50)]
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(["facedyn.usd.rootedit"])
    workers = [context.Process(target=rootedit.attach, args=(root, layer, "synthesized")) for layer in variants]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join(120)
    assert [w.exitcode for w in workers] == [0] * 50
    listed = sublayers(root)
    assert sorted(listed[1:51]) == sorted(f"./{v.name}" for v in variants)  # every variant once, between preview and quasistatic
    assert listed[0] == "./take.preview.usdc" and listed[51:] == FULL[1:]
    lock = tmp_path / ".take.usda.lock"
    assert lock.is_file() and stat.S_IMODE(lock.stat().st_mode) & 0o777 == 0o644


def test_mute_and_unmute_on_disk_put_a_layer_back_at_its_roles_place(tmp_path):
    root = build_take(tmp_path)
    assert mute(root, "./quasistatic.usdc") == ["./take.preview.usdc", "./synthesized.hop.usdc", "./stabilized.usdc", "./capture.usdc"]
    muted = [s for s in stack_status(root) if s.muted]
    assert [s.asset for s in muted] == ["./quasistatic.usdc"] and muted[0].role == "quasistatic"
    attach(root, write_role_layer(root, "take.walk.preview.usdc", "preview"))  # the stack changes meanwhile
    assert unmute(root, tmp_path / "quasistatic.usdc") == [  # named by its file this time
        "./take.walk.preview.usdc", "./take.preview.usdc", "./synthesized.hop.usdc", "./quasistatic.usdc", "./stabilized.usdc", "./capture.usdc"]
    assert not [s for s in stack_status(root) if s.muted]
    mute(root, "stabilized.usdc")
    attach(root, write_role_layer(root, "stabilized.v2.usdc", "stabilized"))
    with pytest.raises(UsageError, match="its stabilized layer is now ./stabilized.v2.usdc"):
        unmute(root, "./stabilized.usdc")
    detach(root, "./stabilized.usdc")  # a muted layer can be detached too
    assert not [s for s in stack_status(root) if s.muted]
    with pytest.raises(UsageError, match=r"no layer ./nothing.usdc in its subLayers \(they are: ./take.walk.preview.usdc"):
        mute(root, "./nothing.usdc")


def test_move_reorders_variants_only(tmp_path):
    root = build_take(tmp_path)
    attach(root, write_role_layer(root, "synthesized.walk.usdc", "synthesized", value=3.5))
    np.testing.assert_allclose(read_take(root)[0].points, base_points() + 3.5, atol=1e-6)
    assert move(root, "./synthesized.hop.usdc", above="./synthesized.walk.usdc")[1:3] == ["./synthesized.hop.usdc", "./synthesized.walk.usdc"]
    _shows(read_take(root)[0], "synthesized")
    assert move(root, "./synthesized.hop.usdc", below="./synthesized.walk.usdc")[1:3] == ["./synthesized.walk.usdc", "./synthesized.hop.usdc"]
    with pytest.raises(UsageError, match=r"cannot move ./stabilized.usdc \(stabilized, rank 10\) next to ./quasistatic.usdc \(quasistatic, rank 20\)"):
        move(root, "./stabilized.usdc", above="./quasistatic.usdc")
    with pytest.raises(UsageError, match="exactly one"):
        move(root, "./stabilized.usdc")


def test_detach_removes_a_layer_and_the_layers_that_read_it_fail_validation(tmp_path):
    from facedyn.usd.validate import validate_take

    root = build_take(tmp_path)
    assert detach(root, str(tmp_path / "stabilized.usdc")) == ["./take.preview.usdc", "./synthesized.hop.usdc", "./quasistatic.usdc", "./capture.usdc"]
    findings = [f for f in validate_take(root) if f.validator.startswith("facedyn:")]
    assert any(f.validator == "facedyn:LayerRequires" and "quasistatic.usdc: a quasistatic layer needs a stabilized layer" in f.message for f in findings)


def test_live_stage_toggles_go_by_role(tmp_path):
    root = build_take(tmp_path)
    stage = Usd.Stage.Open(str(root))
    face = stage.GetPrimAtPath("/Performance/Skull/Face")
    assert sorted(os.path.basename(i) for i in layerstack.result_layers(stage)) == [
        "quasistatic.usdc", "stabilized.usdc", "synthesized.hop.usdc", "take.preview.usdc"]
    assert layerstack.toggle(stage, {"synthesized", "preview"}) is True
    np.testing.assert_allclose(np.asarray(face.GetAttribute("points").Get(1001)), base_points()[0] + OFFSET["quasistatic"], atol=1e-6)
    assert layerstack.toggle(stage, {"synthesized", "preview"}) is False
    layerstack.toggle(stage, {"quasistatic"})
    layerstack.unmute_all(stage)
    assert stage.GetMutedLayers() == []
