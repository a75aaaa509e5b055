"""Staleness is reported exactly when content changed: drawn edits of a take's layers, drawn moves and copies.

A small take (capture, stabilized, quasistatic, synthesized, preview, each computed over
the ones below) is copied once per case and then, by category (a Hypothesis event):
- a layer's points are moved by a drawn vector (zero included), or one point of one frame;
- a layer's file is rewritten with the bytes it had, or only its modification time changes;
- a layer's metadata gains an entry (its bytes change, so what it says changed);
- the take folder is moved or copied to a drawn place, its source and model left behind;
- an input from outside the take is edited: the actor its root records (read by stabilize), a
  BVH given as skull motion, a layer of another take (retarget's source), each recorded as
  the steps record them.
A layer must be stale exactly when the bytes of a layer below it, or of an outside input it
read, differ from what it was computed over; nothing else (paths, times, a source, model,
actor, BVH or source take not found) may make it stale.
"""
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import event, given, settings
from hypothesis import strategies as st
from pxr import Sdf, Vt

from facedyn.performance import Topology, role
from facedyn.usd import schema
from facedyn.usd.layers import LayerContent, write_layer
from facedyn.usd.rootedit import attach
from facedyn.usd.runs import read_elsewhere
from facedyn.usd.stackstatus import stack_status
from facedyn.usd.stage import open_stage
from facedyn.usd.take import read_inputs, read_take_below
from facedyn.usd.timing import Timing

FRAMES = np.arange(1001, 1007, dtype=np.float64)
TIMING = Timing(24.0, 24.0, FRAMES[0], FRAMES[-1])
POINTS = "/Performance/Skull/Face.points"
STACK = [("capture.usdc", "captured"), ("stabilized.usdc", "stabilized"), ("quasistatic.usdc", "quasistatic"),
         ("synthesized.hop.usdc", "synthesized"), ("take.preview.usdc", "preview")]  # weakest first
EDITABLE = [name for name, r in STACK if r != "preview"]  # the layers that author points


def _world(n: int = 4) -> tuple[np.ndarray, Topology]:
    ys, xs = np.mgrid[0:n, 0:n]
    points = np.stack([xs.ravel(), ys.ravel(), np.zeros(n * n)], axis=1).astype(np.float32)
    quads = [[r * n + c, r * n + c + 1, r * n + c + n + 1, r * n + c + n] for r in range(n - 1) for c in range(n - 1)]
    return np.stack([points + 0.1 * i for i in range(len(FRAMES))]), Topology(np.full(len(quads), 4, np.int32),
                                                                               np.asarray(quads, np.int32).ravel())


@pytest.fixture(scope="module")
def studio(tmp_path_factory) -> Path:
    """studio/take (the take), studio/source.txt (what it was imported from), studio/models/removal.model, and the
    outside inputs (OUTSIDE): studio/actors/ada.usda (read by stabilize), studio/mocap/head.bvh and the layers of
    studio/source/ (read by synthesize, as a BVH skull motion and a source take)."""
    studio = tmp_path_factory.mktemp("studio")
    (studio / "source.txt").write_text("the studio's mesh cache")
    (studio / "models").mkdir()
    (studio / "models" / "removal.model").write_bytes(b"weights")
    (studio / "actors").mkdir()
    (studio / "actors" / "ada.usda").write_text("#usda 1.0\n(customLayerData = {dictionary facedyn = {string role = \"actor\"}})\n")
    (studio / "mocap").mkdir()
    (studio / "mocap" / "head.bvh").write_text("HIERARCHY\nROOT Head\n{\n OFFSET 0 0 0\n CHANNELS 3 Xposition Yposition Zposition\n}\n"
                                              "MOTION\nFrames: 2\nFrame Time: 0.0416667\n0 150 0\n0 151 0\n")
    _take(studio, studio / "source", {})
    elsewhere = read_elsewhere(read_inputs(open_stage(studio / "source" / "take.usda")))
    _take(studio, studio / "take", {"stabilized": [studio / "actors" / "ada.usda"], "quasistatic": [studio / "models" / "removal.model"],
                                    "synthesized": [studio / "mocap" / "head.bvh", *elsewhere]})
    return studio


OUTSIDE = {"actors/ada.usda": "stabilized.usdc", "mocap/head.bvh": "synthesized.hop.usdc",
           "source/capture.usdc": "synthesized.hop.usdc", "source/stabilized.usdc": "synthesized.hop.usdc"}  # file: the layer that read it


def _take(studio: Path, take: Path, outside: dict) -> None:
    """The STACK in `take`, each layer computed over the ones below, plus the outside inputs its role reads."""
    take.mkdir()
    world, topology = _world()
    root = take / "take.usda"
    span = (FRAMES[0], FRAMES[-1])
    capture = write_layer(take / "capture.usdc", LayerContent(frames=FRAMES, points=world, topology=topology,
                          face=schema.FaceAttributes(role="captured"), skull=schema.SkullAttributes(solver="identity")),
                          TIMING, schema.Provenance("import", "fuzz", {}, span, [studio / "source.txt"], role="captured"), define=True)
    attach(root, capture, "captured", create_with=TIMING)
    for k, (name, role_name) in enumerate(STACK[1:], start=1):
        _, source = read_take_below(root, role_name)
        models = outside.get(role_name, [])
        if role(role_name).face_role:
            content = LayerContent(frames=FRAMES, points=world + k, face=schema.FaceAttributes(role=role_name))
        else:
            content = LayerContent(frames=FRAMES, display_color=np.full(world.shape, 0.5, np.float32), face=schema.FaceAttributes(role=None))
        provenance = schema.Provenance(role_name, "fuzz", {}, span, list(source.inputs) + models, role=role_name)
        attach(root, write_layer(take / name, content, TIMING, provenance), role_name)
    assert all(s.state == "ok" for s in stack_status(root))


def _edit(draw, take: Path) -> str | None:
    """One drawn edit of a layer in place; the layer edited (None when none was)."""
    name = draw(st.sampled_from(EDITABLE))
    path = take / name
    category = draw(st.sampled_from(["move all", "move one", "same bytes", "touch", "metadata"]))
    event(category)
    if category == "same bytes":
        data = path.read_bytes()
        path.unlink()
        path.write_bytes(data)
    elif category == "touch":
        stat = path.stat()
        os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + draw(st.integers(1, 10**12))))
    else:
        layer = Sdf.Layer.OpenAsAnonymous(str(path))
        if category == "metadata":
            data = dict(layer.customLayerData)
            data[draw(st.sampled_from(["note", "artist"]))] = draw(st.text(max_size=8))
            layer.customLayerData = data
        else:
            times = layer.ListTimeSamplesForPath(POINTS)
            by = np.float32([draw(st.sampled_from([0.0, 1e-3, 5.0, -0.5])) for _ in range(3)])
            for t in times if category == "move all" else [draw(st.sampled_from(times))]:
                points = np.asarray(layer.QueryTimeSample(POINTS, t)).copy()
                if category == "move all":
                    points += by
                else:
                    points[draw(st.integers(0, len(points) - 1))] += by
                layer.SetTimeSample(POINTS, t, Vt.Vec3fArray.FromNumpy(points.astype(np.float32)))
        layer.Export(str(path))
    return name


@settings(max_examples=30)
@given(data=st.data())
def test_a_layer_is_stale_exactly_when_the_bytes_of_a_layer_below_changed(studio, data):
    with tempfile.TemporaryDirectory() as scratch:
        take = Path(scratch) / "take"
        shutil.copytree(studio / "take", take)
        before = {name: (take / name).read_bytes() for name, _ in STACK}
        edited = _edit(data.draw, take)
        changed = edited is not None and (take / edited).read_bytes() != before[edited]
        event("bytes changed" if changed else "bytes unchanged")
        states = {Path(s.asset).name: s for s in stack_status(take / "take.usda")}
        above = [name for name, _ in STACK[[n for n, _ in STACK].index(edited) + 1:]] if changed else []
        assert sorted(n for n, s in states.items() if s.state == "stale") == sorted(above), {n: s.reason for n, s in states.items()}
        for name in above:
            assert "changed since" in states[name].reason


@settings(max_examples=20)
@given(where=st.lists(st.sampled_from(["a", "b b", "ü", ".hidden", "x"]), min_size=0, max_size=3),
       how=st.sampled_from(["copy", "move"]), keep_source=st.booleans(), keep_models=st.booleans(), keep_outside=st.booleans())
def test_a_take_folder_moved_or_copied_stays_current(studio, where, how, keep_source, keep_models, keep_outside):
    event(f"{how}, source {'kept' if keep_source else 'left behind'}, models {'kept' if keep_models else 'left behind'}, "
          f"actor, BVH and source take {'kept' if keep_outside else 'left behind'}")
    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)
        shutil.copytree(studio, scratch / "studio")
        target = scratch.joinpath("elsewhere", *where, "take")
        target.parent.mkdir(parents=True, exist_ok=True)
        (shutil.copytree if how == "copy" else shutil.move)(scratch / "studio" / "take", target)
        for kept, names in ((keep_source, ["source.txt"]), (keep_models, ["models"]), (keep_outside, ["actors", "mocap", "source"])):
            for name in names if kept else []:
                (shutil.copytree if name != "source.txt" else shutil.copy)(studio / name, target.parent / name)
        states = {Path(s.asset).name: s for s in stack_status(target / "take.usda")}
        assert {n: s.state for n, s in states.items()} == {name: "ok" for name, _ in STACK}, {n: s.reason for n, s in states.items()}
        assert bool(states["quasistatic.usdc"].unchecked) == (not keep_models)
        assert bool(states["stabilized.usdc"].unchecked) == bool(states["synthesized.hop.usdc"].unchecked) == (not keep_outside)
        assert not states["capture.usdc"].unchecked


@settings(max_examples=30)
@given(data=st.data())
def test_a_layer_is_stale_exactly_when_an_outside_input_it_read_changed(studio, data):
    """The actor, the BVH and the source take's layers: an edit of their bytes makes stale the layer that read them,
    and only it; the same bytes rewritten or a newer modification time do not."""
    with tempfile.TemporaryDirectory() as scratch:
        copy = Path(scratch) / "studio"
        shutil.copytree(studio, copy)
        name = data.draw(st.sampled_from(sorted(OUTSIDE)))
        path = copy / name
        before = path.read_bytes()
        category = data.draw(st.sampled_from(["content", "same bytes", "touch"]))
        event(f"{name}: {category}")
        if category == "content" and path.suffix == ".usdc":
            _edit_points(data.draw, path)
        elif category == "content":
            path.write_bytes(before + data.draw(st.sampled_from([b"\n", b" ", b"0 152 0\n"])))
        elif category == "same bytes":
            path.unlink()
            path.write_bytes(before)
        else:
            stat = path.stat()
            os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + data.draw(st.integers(1, 10**12))))
        changed = path.read_bytes() != before
        states = {Path(s.asset).name: s for s in stack_status(copy / "take" / "take.usda")}
        stale = sorted(n for n, s in states.items() if s.state == "stale")
        assert stale == ([OUTSIDE[name]] if changed else []), {n: s.reason for n, s in states.items()}
        if changed:
            assert states[OUTSIDE[name]].reason == f"its input ../{name} changed since it was computed"


def _edit_points(draw, path: Path) -> None:
    """Every point of one drawn frame of a layer moved by a drawn, non-zero vector."""
    layer = Sdf.Layer.OpenAsAnonymous(str(path))
    t = draw(st.sampled_from(layer.ListTimeSamplesForPath(POINTS)))
    by = np.float32([draw(st.sampled_from([1e-3, 5.0, -0.5])) for _ in range(3)])
    layer.SetTimeSample(POINTS, t, Vt.Vec3fArray.FromNumpy((np.asarray(layer.QueryTimeSample(POINTS, t)) + by).astype(np.float32)))
    layer.Export(str(path))


@settings(max_examples=25)
@given(data=st.data())
def test_layers_and_validate_agree_on_each_layer_after_a_drawn_edit_of_the_stack(studio, data):
    """After `layers --mute quasistatic.usdc` layers showed the synthesized layer ok while validate failed it; a
    truncated layer was listed ok while validate refused the take. Each state `layers` shows is what validate reports."""
    from facedyn.usd.errors import TakeError
    from facedyn.usd.rootedit import detach, mute
    from facedyn.usd.validate import validate_take

    with tempfile.TemporaryDirectory() as scratch:
        take = Path(scratch) / "take"
        shutil.copytree(studio / "take", take)
        root = take / "take.usda"
        category = data.draw(st.sampled_from(["content", "mute", "detach", "truncate", "delete"]))
        name = data.draw(st.sampled_from([n for n, _ in STACK[1:]]))
        event(category)
        if category == "content":
            _edit(data.draw, take)
        elif category in ("mute", "detach"):
            (mute if category == "mute" else detach)(root, f"./{name}")
        elif category == "truncate":
            (take / name).write_bytes((take / name).read_bytes()[: data.draw(st.integers(0, (take / name).stat().st_size - 1))])
        else:
            (take / name).unlink()
        statuses = [s for s in stack_status(root) if not s.muted]
        try:
            findings = validate_take(root)
        except TakeError as exc:  # a layer USD cannot open: every reader refuses the take, and layers says which
            assert [s.asset for s in statuses if s.state == "unreadable"] == [f"./{name}"], (str(exc), [s.state for s in statuses])
            assert str(take / name) in str(exc) and "\n" not in str(exc)
            return
        by_file = {}
        for f in findings:
            if f.validator in ("facedyn:Stale", "facedyn:LayerRequires", "facedyn:LayerStack"):
                by_file.setdefault(Path(f.file).resolve(), set()).add(f.validator)
        for s in statuses:
            assert s.state != "unreadable"
            reported = by_file.get(s.path.resolve(), set())
            expected = {"stale": {"facedyn:Stale"} if s.stale else set(), "missing": {"facedyn:LayerStack"}, "ok": set()}[s.state]
            if s.needs:
                expected = expected | {"facedyn:LayerRequires"}
            assert reported == expected, (s.asset, s.state, s.reason, s.needs, reported)
