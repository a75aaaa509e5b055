"""The person-independent removal model (facedyn.dynamics.portable): any mesh, the same answer in any skull frame."""
from pathlib import Path

import numpy as np
import pytest
from synthetic_face import curved_sheet, jiggle, platform_motion, top_rows

from facedyn.dynamics.modelfile import load_model
from facedyn.dynamics.portable import face_frame, for_take, is_portable
from facedyn.dynamics.removal import remove_dynamics
from facedyn.geometry import quaternion
from facedyn.models import resolve_model, shipped_path
from facedyn.errors import UsageError
from facedyn.performance import Performance, Topology

FPS = 60.0
ROWS, COLS = 24, 24


@pytest.fixture(scope="module")
def model():
    return load_model(shipped_path("default"))


def sheet_take(frames: int = 80) -> Performance:
    """A curved sheet (a mesh no training face has) on a 7 Hz platform, its lower rows jiggling.

    Jittered, so that no two vertices tie for the farthest-point sampling: on a regular
    grid a rounding difference picks other (equally good) samples.
    """
    rest, topology = curved_sheet(ROWS, COLS)
    rest = rest + np.random.default_rng(5).uniform(-0.1, 0.1, rest.shape)
    t, q = platform_motion(frames, FPS, 7.0)
    weights = np.zeros(len(rest), np.float32)
    weights[top_rows(ROWS, COLS, 4)] = 1.0
    free = 1.0 - np.clip((rest[:, 1] + 4.0) / 8.0, 0.0, 1.0)  # more jiggle low on the sheet
    points = rest[None] + 0.5 * jiggle(t, q, FPS)[:, None, :] * free[None, :, None]
    return Performance(points=points.astype(np.float32), frames=np.arange(frames, dtype=np.float64), fps=FPS, topology=topology,
                       skull_translate=t, skull_orient=q, rest_points=rest.astype(np.float32), rigid_weights=weights)


def moved(perf: Performance, turn: np.ndarray, shift: np.ndarray) -> Performance:
    """The same take in another skull frame p' = turn p + shift (world points unchanged)."""
    back = quaternion.conjugate(quaternion.from_matrix(turn))
    orient = quaternion.multiply(perf.skull_orient, np.broadcast_to(back, perf.skull_orient.shape))
    translate = perf.skull_translate - quaternion.to_matrix(orient) @ shift
    return perf.with_changes(points=(perf.points @ turn.T + shift).astype(np.float32), rest_points=(perf.rest_points @ turn.T + shift).astype(np.float32),
                             skull_translate=translate, skull_orient=orient)


def yaw(degrees: float) -> np.ndarray:
    return quaternion.to_matrix(quaternion.from_rotvec(np.array([0.0, np.radians(degrees), 0.0])))


def removed(model, perf: Performance):
    return remove_dynamics(perf.points, perf.skull_translate, perf.skull_orient, perf.fps, for_take(model, perf), backend="numpy", device="cpu")


def test_the_shipped_model_is_person_independent_and_says_how_it_was_built(model):
    assert is_portable(model) and model.kind == "removal"
    build = model.info["training"]["build"]
    assert build["command"].startswith("python -m facedyn.sim.default_model") and build["takes"] > 0 and build["epochs"] >= 1
    assert shipped_path("default").stat().st_size < 1 << 20


def test_it_removes_on_a_mesh_it_was_never_trained_on(model):
    perf = sheet_take()
    assert perf.topology.fingerprint() != model.fingerprint
    quasistatic, offsets = removed(model, perf)
    assert quasistatic.shape == offsets.shape == perf.points.shape and np.isfinite(offsets).all()
    np.testing.assert_allclose(quasistatic, perf.points - offsets, atol=1e-5)
    assert np.abs(offsets).max() > 1e-4  # it predicts something
    assert np.abs(offsets[:, top_rows(ROWS, COLS, 4)]).max() < 1e-6  # nothing on the rigid band


def test_the_answer_does_not_depend_on_the_takes_yaw_or_the_skull_frames_origin(model):
    perf = sheet_take()
    _, offsets = removed(model, perf)
    for degrees, shift in ((70.0, np.zeros(3)), (-150.0, np.array([3.0, -12.0, 40.0])), (0.0, np.array([-25.0, 4.0, 9.0]))):
        turn = yaw(degrees)
        quasistatic, turned = removed(model, moved(perf, turn, shift))
        np.testing.assert_allclose(turned @ turn, offsets, atol=2e-4 * np.abs(offsets).max() + 1e-6)


def test_the_take_is_set_up_from_its_rest_or_else_its_first_frame(model):
    perf = sheet_take()
    assert for_take(model, perf).info["rest"] == "the take's rest points"
    assert for_take(model, perf.with_changes(rest_points=None)).info["rest"] == "the take's first frame"


def test_the_face_frame_looks_where_the_face_does():
    rest, topology = curved_sheet(ROWS, COLS)  # faces +Z
    turn = yaw(90.0)  # now faces +X
    frame = face_frame(rest @ turn.T, topology)
    np.testing.assert_allclose(frame.rotation[2], [1.0, 0.0, 0.0], atol=0.02)
    np.testing.assert_allclose(frame.rotation[1], [0.0, 1.0, 0.0])
    inward = Topology(topology.face_vertex_counts, np.asarray(topology.face_vertex_indices).reshape(-1, 3)[:, ::-1].ravel())
    np.testing.assert_allclose(face_frame(rest @ turn.T, inward).rotation, frame.rotation, atol=1e-12)  # winding does not matter
    centred = frame.points(rest @ turn.T)
    np.testing.assert_allclose(centred.min(axis=0), -centred.max(axis=0), atol=1e-9)  # origin: the box's centre


def test_a_model_name_that_is_not_shipped_is_a_clear_error(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(UsageError, match="no shipped model of that name .shipped: default"):
        resolve_model("defualt")
    assert resolve_model("default") == shipped_path("default")
    (tmp_path / "default").write_bytes(b"x")  # a file of that name wins over the shipped model
    assert resolve_model("default") == Path("default")
