"""USD takes, valid and mutated: every processor's read gives a sound take or a FacedynError naming a file.

A small valid take (a capture and a stabilized layer under a root, all .usda) is mutated
once per case, by category (a Hypothesis event, counted by --hypothesis-show-statistics):
samples dropped, NaN/inf/huge points, a point or face count changed, bad topology, bad
units/up axis/rates, samples moved between frames, a skull unkeyed, zero or non-unit
quaternions, or the stabilized layer's text mutated like the other fuzzed formats. A read
that succeeds must be sound: finite points, consecutive whole frames, unit quaternions,
centimetres and Y up; so a wrong take cannot pass silently.
"""
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import event, given
from hypothesis import strategies as st
from mutate import mutated, outcome
from pxr import Gf, Sdf, UsdGeom, Vt

from facedyn.geometry import quaternion
from facedyn.performance import Topology
from facedyn.usd import schema
from facedyn.usd.layers import LayerContent, write_layer, write_take_root
from facedyn.usd.take import read_take, read_take_below
from facedyn.usd.timing import Timing

FACE, SKULL = "/Performance/Skull/Face", "/Performance/Skull"
FRAMES = np.arange(1001, 1007, dtype=np.float64)
READERS = [("take", None), ("stabilize", "stabilized"), ("remove", "quasistatic"), ("synthesize", "synthesized"), ("preview", "preview")]
CATEGORIES = ("unchanged", "samples dropped", "bad points", "point count", "topology", "units", "rates",
              "between frames", "skull unkeyed", "bad quaternion", "text")


@pytest.fixture(scope="module")
def valid_take(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("take")
    n = 4
    ys, xs = np.mgrid[0:n, 0:n]
    points = np.stack([xs.ravel(), ys.ravel(), np.zeros(n * n)], axis=1).astype(np.float32)
    quads = [[r * n + c, r * n + c + 1, r * n + c + n + 1, r * n + c + n] for r in range(n - 1) for c in range(n - 1)]
    topology = Topology(np.full(len(quads), 4, np.int32), np.asarray(quads, np.int32).ravel())
    world = np.stack([points + 0.1 * i for i in range(len(FRAMES))]).astype(np.float32)
    timing = Timing(120.0, 120.0, FRAMES[0], FRAMES[-1])
    rng = (FRAMES[0], FRAMES[-1])
    capture = write_layer(folder / "capture.usda", LayerContent(frames=FRAMES, points=world, topology=topology,
                          face=schema.FaceAttributes(role="captured"), skull=schema.SkullAttributes(solver="identity")),
                          timing, schema.Provenance("import", "fuzz", {}, rng, []), define=True)
    orient = quaternion.from_axis_angle(np.array([0.0, 1.0, 0.0]), np.linspace(0, 0.3, len(FRAMES)))
    stabilized = write_layer(folder / "stabilized.usda", LayerContent(frames=FRAMES, points=world, topology=topology,
                             face=schema.FaceAttributes(role="stabilized"), skull=schema.SkullAttributes(solver="fuzz"),
                             skull_translate=np.zeros((len(FRAMES), 3)), skull_orient=orient),
                             timing, schema.Provenance("stabilize", "fuzz", {}, rng, []))
    write_take_root(folder / "take.usda", [stabilized, capture], timing)
    return folder


def _mutate(draw, folder: Path) -> None:
    """One drawn mutation of the take in `folder` (its capture, stabilized layer or root)."""
    category = draw(st.sampled_from(CATEGORIES))
    event(f"mutation: {category}")
    name = draw(st.sampled_from(["capture.usda", "stabilized.usda"]))
    if category == "text":
        path = folder / "stabilized.usda"
        path.write_bytes(draw(mutated(path.read_text())))
        return
    layer = Sdf.Layer.FindOrOpen(str(folder / ("take.usda" if category in ("units", "rates") else name)))
    points = Sdf.Path(FACE + ".points")
    frame = float(draw(st.sampled_from(list(FRAMES))))
    if category == "samples dropped":
        for t in draw(st.lists(st.sampled_from(list(FRAMES)), min_size=1, max_size=5)):
            layer.EraseTimeSample(points, float(t))
    elif category == "bad points":
        value = np.array(layer.QueryTimeSample(points, frame), np.float32)
        value[draw(st.integers(0, len(value) - 1)), draw(st.integers(0, 2))] = draw(st.sampled_from([np.nan, np.inf, -np.inf, 1e30]))
        layer.SetTimeSample(points, frame, Vt.Vec3fArray.FromNumpy(value))
    elif category == "point count":
        value = np.array(layer.QueryTimeSample(points, frame), np.float32)
        layer.SetTimeSample(points, frame, Vt.Vec3fArray.FromNumpy(value[: draw(st.integers(0, len(value) - 1))]))
    elif category == "topology":
        spec = layer.GetAttributeAtPath(FACE + draw(st.sampled_from([".faceVertexIndices", ".faceVertexCounts"])))
        if spec is None:
            return
        values = list(spec.default or [])
        if values:
            values[draw(st.integers(0, len(values) - 1))] = draw(st.sampled_from([-1, 0, 2, 10**6]))
        spec.default = Vt.IntArray(values[: draw(st.integers(0, len(values)))])
    elif category == "units":
        key = draw(st.sampled_from([UsdGeom.Tokens.metersPerUnit, UsdGeom.Tokens.upAxis]))
        layer.pseudoRoot.SetInfo(key, draw(st.sampled_from([1.0, 0.1, 0.0, -1.0, -0.01, float("nan"), float("inf")]))
                                 if key == UsdGeom.Tokens.metersPerUnit else draw(st.sampled_from(["Z", "X"])))
    elif category == "rates":
        rate = draw(st.sampled_from([30.0, 24.0, 1.0, 119.0, 1e6, 0.0, -24.0, -120.0, float("nan"), float("inf")]))
        which = draw(st.sampled_from(["both", "timeCodesPerSecond", "framesPerSecond"]))
        if which in ("both", "timeCodesPerSecond"):
            layer.timeCodesPerSecond = rate
        if which in ("both", "framesPerSecond"):
            layer.framesPerSecond = rate
    elif category == "between frames":
        value = layer.QueryTimeSample(points, frame)
        layer.EraseTimeSample(points, frame)
        layer.SetTimeSample(points, frame + draw(st.sampled_from([0.5, 0.25, 0.001, 10.0])), value)
    elif category == "skull unkeyed":
        spec = Sdf.Path(SKULL + draw(st.sampled_from([".xformOp:orient", ".xformOp:translate"])))
        attr = layer.GetAttributeAtPath(spec)
        if attr is not None:
            for t in list(layer.ListTimeSamplesForPath(spec))[: draw(st.integers(1, 6))]:
                layer.EraseTimeSample(spec, t)
            attr.ClearDefaultValue()
    elif category == "bad quaternion":
        layer = Sdf.Layer.FindOrOpen(str(folder / "stabilized.usda"))
        q = draw(st.sampled_from([(0, 0, 0, 0), (2, 0, 0, 0), (0.5, 0.5, 0, 0), (float("nan"), 0, 0, 0)]))
        layer.SetTimeSample(Sdf.Path(SKULL + ".xformOp:orient"), frame, Gf.Quatd(*q))
    layer.Save()


def _check_sound(perf) -> None:
    assert np.isfinite(perf.points).all() and perf.points.shape[1] > 0
    assert np.array_equal(perf.frames, np.round(perf.frames)) and (np.diff(perf.frames) == 1).all()
    assert perf.meters_per_unit == 0.01 and perf.up_axis == "Y"
    assert np.isfinite(perf.fps) and perf.fps > 0
    assert perf.topology.face_vertex_indices.max() < perf.point_count
    if perf.skull_orient is not None:
        assert np.allclose(np.linalg.norm(perf.skull_orient, axis=1), 1.0, atol=1e-3)


@given(st.data())
def test_every_processor_read_gives_a_sound_take_or_a_clear_error(valid_take, data):
    with tempfile.TemporaryDirectory() as scratch:
        folder = Path(scratch) / "take"
        shutil.copytree(valid_take, folder)
        _mutate(data.draw, folder)
        files = [folder / name for name in ("take.usda", "capture.usda", "stabilized.usda")]
        for processor, role in READERS:
            read = (lambda: read_take(files[0])) if role is None else (lambda role=role: read_take_below(files[0], role))
            result = outcome(files, read)
            event(f"{processor}: {'read' if result else 'refused'}")
            if result is not None:
                _check_sound(result[0])
        for layer in files:  # nothing stays open between cases
            found = Sdf.Layer.Find(str(layer))
            if found is not None:
                found.Reload(force=True)


SCALE_VALUES = [0.0, -0.0, -1.0, -24.0, 1e-300, float("nan"), float("inf"), -float("inf"), 0.01, 1.0, 24.0, 120.0]


@given(st.sampled_from(["metersPerUnit", "timeCodesPerSecond", "framesPerSecond"]), st.sampled_from(SCALE_VALUES))
def test_an_import_source_with_non_positive_or_non_finite_units_or_rates_is_refused(valid_take, field, value):
    """A source's metersPerUnit scales every point (0 collapses them, -1 mirrors them) and its rates every frame:
    import reads one only where they are finite and above 0, and its points are then finite."""
    from facedyn.usd.source import open_mesh_source

    event(f"{field}: {'fine' if np.isfinite(value) and value > 0 else 'refused'}")
    with tempfile.TemporaryDirectory() as scratch:
        source = Path(scratch) / "source.usdc"
        layer = Sdf.Layer.CreateNew(str(source))  # a crate file keeps values the text parser would refuse
        layer.TransferContent(Sdf.Layer.FindOrOpen(str(valid_take / "capture.usda")))
        if field == "metersPerUnit":
            layer.pseudoRoot.SetInfo(UsdGeom.Tokens.metersPerUnit, value)
        else:
            setattr(layer, field, value)
        layer.Save()
        mesh = outcome([source], lambda: open_mesh_source(source))
        if not (np.isfinite(value) and value > 0):
            assert mesh is None
        elif mesh is not None:
            points = outcome([source], lambda: mesh.read(mesh.time_codes))
            assert points is None or np.isfinite(points).all()
