"""The actor's learned spread: fitted on a session's skin motion, carried by model files, applied by the propagator."""
from dataclasses import dataclass

import numpy as np
import pytest
import torch
from synthetic_face import curved_sheet, top_rows

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.modelfile import DynamicsModel, ModelFileError, describe_model, load_model, save_model
from facedyn.dynamics.network import Network, removal_spec
from facedyn.dynamics.spread import ARRAYS, INTO, Spread, fit_model_spread, fit_spread, spread_of, with_spread

ROWS, COLS = 16, 12


@dataclass
class Take:
    """What fit_spread reads of a session take (as facedyn.dynamics.training_sequence.TrainingSequence holds it)."""
    points: np.ndarray
    translate: np.ndarray
    orient: np.ndarray
    space: str = "skull"


@pytest.fixture(scope="module")
def face():
    pts, topo = curved_sheet(ROWS, COLS)
    return FaceSetup.build(topo, pts, rigid_vertices=top_rows(ROWS, COLS, 2), sample_count=20)


def patterns(face, count=4, seed=0):
    """(count, N, 3) smooth but not bi-harmonic motion patterns, zero on the rigid rows: how this sheet's skin moves."""
    rng = np.random.default_rng(seed)
    pts = face.rest_points
    height = (pts[:, 1] - pts[:, 1].min()) / np.ptp(pts[:, 1])
    out = []
    for _ in range(count):
        centre, width = pts[rng.integers(len(pts))], rng.uniform(2.0, 4.0)
        bump = np.exp(-np.sum((pts - centre) ** 2, axis=1) / (2 * width ** 2)) * np.sin(3 * height * np.pi)
        out.append(bump[:, None] * rng.normal(size=3))
    moving = np.stack(out)
    moving[:, face.rigid_vertices] = 0.0
    return moving


def session(face, takes=6, frames=80, seed=1):
    rng = np.random.default_rng(seed)
    modes = patterns(face)
    identity = np.tile([1.0, 0.0, 0.0, 0.0], (frames, 1))
    return [Take((face.rest_points + np.einsum("fk,knc->fnc", rng.normal(size=(frames, len(modes))), modes)).astype(np.float32),
                 np.zeros((frames, 3)), identity) for _ in range(takes)]


def model_of(face):
    torch.manual_seed(0)
    return DynamicsModel("removal", Network(removal_spec()), face, 60.0, {"skull": 10, "skin": 10, "target": 10}, {})


def test_the_spread_recovers_how_the_session_moves_between_the_samples(face):
    propagator = model_of(face).propagator()
    spread, record = fit_spread(session(face), propagator, settle_frames=5, rank=12)
    assert record["session_missed_with_spread"] < 0.05 < 0.3 < record["session_missed_by_smoothest"]
    # a new take of the same skin: the samples' motion spread with the correction is the whole motion
    motion = session(face, takes=1, seed=7)[0].points - face.rest_points
    plain = propagator.apply(motion[:, face.samples])
    corrected = plain.copy()
    spread.add_into(motion[:, face.samples], corrected)
    error = lambda u: np.sqrt(np.sum((u - motion) ** 2) / np.sum(motion ** 2))  # noqa: E731
    assert error(corrected) < 0.1 * error(plain)
    # it never moves a sample (exact as before), and a rigid region the session never moves stays all but still
    assert not np.intersect1d(spread.vertices, face.samples).size
    assert np.abs(corrected[:, face.rigid_vertices]).max() < 0.01 * np.abs(motion).max()


def test_a_model_file_carries_its_spread_and_its_propagator_applies_it(face, tmp_path):
    model = model_of(face)
    spread, record = fit_spread(session(face), model.propagator(), settle_frames=5, rank=12)
    path = save_model(with_spread(model, spread, record), tmp_path / "actor.removal")
    loaded = load_model(path)
    assert loaded.info["spread"] == record and spread_of(loaded)[1] == record and describe_model(path)["spread"] == record  # inspect shows it
    d = np.random.default_rng(3).normal(0, 0.1, (4, len(face.samples), 3)).astype(np.float32)
    expected = model.propagator().apply(d)
    spread.add_into(d, expected)
    np.testing.assert_allclose(loaded.propagator().apply(d), expected, atol=1e-5)
    assert spread_of(model) is None and model.propagator().spread is None  # a model without one spreads as before


@pytest.mark.parametrize("edit, message", [
    (lambda a: a.pop(INTO), "incomplete"),
    (lambda a: a.update({INTO: a[INTO][:-3]}), r"need \(3S, r\) and \(r, 3V\)"),
    (lambda a: a.update({"spread_vertices": a["spread_vertices"] + 10_000}), "not distinct vertex indices"),
])
def test_a_damaged_spread_is_a_clear_error_on_load(face, tmp_path, edit, message):
    model = model_of(face)
    spread, record = fit_spread(session(face), model.propagator(), settle_frames=5, rank=12)
    arrays = {**model.arrays, **spread.arrays()}
    edit(arrays)
    path = save_model(DynamicsModel(**{**model.__dict__, "arrays": arrays, "_propagator": None}), tmp_path / "bad.removal")
    with pytest.raises(ModelFileError, match=message):
        load_model(path)
    assert set(ARRAYS) == set(spread.arrays())
    with pytest.raises(ValueError, match=message):
        Spread.from_arrays(arrays, len(face.samples), face.point_count)


def test_a_session_whose_skin_never_moves_learns_a_spread_that_adds_nothing(face):
    still = [Take(np.repeat(face.rest_points[None], 40, axis=0).astype(np.float32), take.translate[:40], take.orient[:40])
             for take in session(face, takes=2)]
    spread, record = fit_spread(still, model_of(face).propagator(), settle_frames=5, rank=12)
    offsets = np.zeros((3, face.point_count, 3), np.float32)
    spread.add_into(np.ones((3, len(face.samples), 3), np.float32), offsets)
    assert np.all(offsets == 0) and record["session_missed_by_smoothest"] == 0


def test_refitting_a_model_that_carries_a_spread_fits_against_the_bi_laplacian_alone(face):
    first = fit_model_spread(model_of(face), session(face), settle_s=5 / 60)
    again = fit_model_spread(first, session(face), settle_s=5 / 60)
    np.testing.assert_array_equal(spread_of(again)[0].into, spread_of(first)[0].into)
    assert spread_of(again)[1] == spread_of(first)[1]
