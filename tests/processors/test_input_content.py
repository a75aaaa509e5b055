"""Issue 39 item 4: the files a step reads besides its take's layers are inputs identified by content.

The actor a take root records (used by `stabilize` without --actor), the layers of the take
`retarget --source` reads, and a BVH given to `synthesize --skull-motion`: editing any of them
makes the layer computed from it stale in `layers` and `validate` alike; the same bytes
rewritten, or the take folder moved or copied, keep it current (what is left behind is
unchecked, not stale).
"""
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest
from pxr import Sdf, Vt

from facedyn.cli import main
from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.modelfile import save_model
from facedyn.dynamics.response import response_template
from facedyn.performance import Actor
from facedyn.usd.actor_asset import write_actor
from facedyn.usd.runs import facedyn_metadata
from facedyn.usd.stackstatus import stack_status
from facedyn.usd.validate import validate_take

from usd_fixtures import write_mesh_cache

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "dynamics"))
from synthetic_face import curved_sheet, top_rows  # noqa: E402

ROWS, COLS, FRAMES, FPS = 8, 6, 24, 24.0
POINTS = "/Performance/Skull/Face.points"


def cli(*argv):
    return main([str(a) for a in argv] + ["-q"])


def head_bvh(path: Path, bob_cm: float) -> Path:
    """A head alone bobbing up and down (its conventions given on the command line)."""
    rows = "\n".join(f"0 {150 + bob_cm * np.sin(2 * np.pi * t):.6f} 0" for t in np.arange(2 * FRAMES) / FPS)
    path.write_text(f"HIERARCHY\nROOT Head\n{{\n OFFSET 0 0 0\n CHANNELS 3 Xposition Yposition Zposition\n}}\n"
                    f"MOTION\nFrames: {2 * FRAMES}\nFrame Time: {1 / FPS:.7f}\n{rows}\n")
    return path


@pytest.fixture(scope="module")
def studio(tmp_path_factory) -> Path:
    """studio/{actors/ada.usda, head.bvh, r.response, A/, B/}: A stabilized with the actor its root records; B
    stabilized, removed, synthesized with head.bvh and retargeted from A, every layer attached to B's root."""
    studio = tmp_path_factory.mktemp("studio")
    points, topology = curved_sheet(ROWS, COLS)
    rigid = np.zeros(len(points))
    rigid[top_rows(ROWS, COLS, 3)] = 1.0
    t = np.arange(FRAMES)
    angles = np.stack([0.05 * np.sin(t / 3), 0.03 * np.cos(t / 4), 0.01 * t / FRAMES], 1)
    world = np.stack([_rotated(points, a) + [0.5 * np.sin(i / 5), 0.2 * i / FRAMES, 0] for i, a in enumerate(angles)])
    world[:, rigid < 0.5, 2] += 0.05 * np.sin(t / 2)[:, None]
    cache = write_mesh_cache(studio / "cache.usda", world, topology.face_vertex_counts, topology.face_vertex_indices, fps=FPS)
    (studio / "actors").mkdir()
    write_actor(studio / "actors" / "ada.usda", Actor("ada", points, topology, rigid_weights=rigid, source="neutral"))
    face = FaceSetup.build(topology, points, rigid_vertices=top_rows(ROWS, COLS, 3), sample_count=6)
    response = save_model(response_template(face, FPS, {"calibration": {"response": "linear", "takes": []}}), studio / "r.response")
    bvh = head_bvh(studio / "head.bvh", 1.0)
    for name in ("A", "B"):
        (studio / name).mkdir()
        assert cli("import", cache, "-o", studio / name / "capture.usdc", "--actor", studio / "actors" / "ada.usda") == 0
        root = studio / name / "take.usda"
        assert cli("stabilize", root, "-o", studio / name / "stabilized.usdc", "--attach", root) == 0  # the recorded actor
    b = studio / "B"
    root = b / "take.usda"
    assert cli("remove", root, "--model", response, "-o", b / "quasistatic.usdc", "--attach", root) == 0
    assert cli("synthesize", root, "--model", response, "--skull-motion", bvh, "--bvh-units", "1", "--bvh-up", "+y",
               "--bvh-forward", "+z", "-o", b / "synthesized.bob.usdc", "--attach", root) == 0
    assert cli("retarget", root, "--model", response, "--source", studio / "A" / "take.usda", "-o", b / "retargeted.usdc",
               "--attach", root) == 0
    assert _states(root) == dict.fromkeys(LAYERS, "ok")
    return studio


LAYERS = ("./retargeted.usdc", "./synthesized.bob.usdc", "./quasistatic.usdc", "./stabilized.usdc", "./capture.usdc")


def _rotated(points: np.ndarray, angles: np.ndarray) -> np.ndarray:
    cx, cy, cz = np.cos(angles)
    sx, sy, sz = np.sin(angles)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return points @ (rz @ ry @ rx).T


def _states(root: Path) -> dict[str, str]:
    return {s.asset: s.state for s in stack_status(root)}


def _agree_with_validate(root: Path) -> None:
    """validate reports as stale exactly the layers `layers` does."""
    stale = {str(s.path) for s in stack_status(root) if s.state == "stale"}
    assert {f.file for f in validate_take(root) if f.validator == "facedyn:Stale"} == stale


@pytest.fixture
def copy(studio, tmp_path) -> Path:
    shutil.copytree(studio, tmp_path / "studio")
    return tmp_path / "studio"


def test_the_actor_the_bvh_and_the_source_takes_layers_are_recorded_inputs(studio):
    def inputs(name):
        return list(facedyn_metadata(studio / "B" / name)["inputs"])

    assert inputs("stabilized.usdc") == ["./capture.usdc", "../actors/ada.usda"]  # no --actor: the root's
    assert inputs("synthesized.bob.usdc")[-1] == "../head.bvh"
    assert inputs("retargeted.usdc")[-3:] == ["../A/stabilized.usdc", "../A/capture.usdc", "../A/take.usda"]


def test_an_edit_of_the_recorded_actor_makes_the_stabilized_layer_stale_until_it_is_re_run(copy):
    root = copy / "B" / "take.usda"
    actor = Sdf.Layer.OpenAsAnonymous(str(copy / "actors" / "ada.usda"))
    path = "/Actor/Skull/Neutral.points"
    neutral = np.array(actor.GetAttributeAtPath(path).default, np.float32)
    neutral[0] += 0.5  # a soft vertex of the neutral moved (the sheet's bottom row)
    actor.GetAttributeAtPath(path).default = Vt.Vec3fArray.FromNumpy(neutral)
    actor.Export(str(copy / "actors" / "ada.usda"))
    status = {s.asset: s for s in stack_status(root)}
    assert status["./stabilized.usdc"].state == "stale"
    assert status["./stabilized.usdc"].reason == "its input ../actors/ada.usda changed since it was computed"
    assert [a for a, s in status.items() if s.state == "stale"] == ["./stabilized.usdc"]
    _agree_with_validate(root)
    assert cli("stabilize", root, "-o", copy / "B" / "stabilized.usdc", "--attach", root) == 0
    states = _states(root)
    assert states["./stabilized.usdc"] == "ok" and states["./quasistatic.usdc"] == "stale"  # re-run with the new neutral


def test_an_edit_of_the_bvh_makes_the_synthesized_layer_stale_and_the_same_bytes_do_not(copy):
    root = copy / "B" / "take.usda"
    before = (copy / "head.bvh").read_bytes()
    head_bvh(copy / "head.bvh", 2.0)
    status = {s.asset: s for s in stack_status(root)}
    assert [a for a, s in status.items() if s.state == "stale"] == ["./synthesized.bob.usdc"]
    assert status["./synthesized.bob.usdc"].reason == "its input ../head.bvh changed since it was computed"
    _agree_with_validate(root)
    (copy / "head.bvh").write_bytes(before)
    assert _states(root) == dict.fromkeys(LAYERS, "ok")


def test_an_edit_of_a_layer_of_the_source_take_makes_the_retargeted_layer_stale(copy):
    root = copy / "B" / "take.usda"
    layer = Sdf.Layer.OpenAsAnonymous(str(copy / "A" / "stabilized.usdc"))
    for t in layer.ListTimeSamplesForPath(POINTS):
        layer.SetTimeSample(POINTS, t, Vt.Vec3fArray.FromNumpy(np.asarray(layer.QueryTimeSample(POINTS, t), np.float32) + 1.0))
    layer.Export(str(copy / "A" / "stabilized.usdc"))
    status = {s.asset: s for s in stack_status(root)}
    assert [a for a, s in status.items() if s.state == "stale"] == ["./retargeted.usdc"]
    assert status["./retargeted.usdc"].reason == "its input ../A/stabilized.usdc changed since it was computed"
    _agree_with_validate(root)


@pytest.mark.parametrize("how", ["the studio copied", "the take copied alone", "the take moved alone"])
def test_a_take_moved_or_copied_stays_current(copy, tmp_path, how):
    if how == "the studio copied":
        where = shutil.copytree(copy, tmp_path / "elsewhere" / "studio") / "B"
    else:
        where = (shutil.copytree if "copied" in how else shutil.move)(copy / "B", tmp_path / "elsewhere" / "deeper" / "B")
    status = {s.asset: s for s in stack_status(Path(where) / "take.usda")}
    assert {a: s.state for a, s in status.items()} == dict.fromkeys(LAYERS, "ok")
    left_behind = {a: s.unchecked for a, s in status.items() if s.unchecked}
    if how == "the studio copied":
        assert left_behind == {}
    else:  # the actor, the BVH, the model and A are not found from there: unchecked, never stale
        assert set(left_behind) == {"./stabilized.usdc", "./synthesized.bob.usdc", "./quasistatic.usdc", "./retargeted.usdc"}
        assert left_behind["./stabilized.usdc"] == "its input ../actors/ada.usda is not found from here; its content was not checked"
