"""An actor's linear response fitted on held expressions without truth (facedyn.dynamics.response)."""
import numpy as np
import pytest

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.modelfile import DynamicsModel, load_model, save_model
from facedyn.dynamics.network import Network, removal_spec
from facedyn.dynamics.response import RIDGE, RIDGES, fit_linear_response
from facedyn.dynamics.synthesis import synthesize_dynamics
from facedyn.dynamics.synthesis_training import synthesis_config, train_synthesis
from facedyn.dynamics.training_sequence import TrainingSequence
from facedyn.sim.corpus import TakeSpec, simulate_take
from facedyn.sim.default_face import default_face
from facedyn.sim.tissue import TissueParams

FPS = 120.0
TISSUE = TissueParams(soft_hz=6.5, damping_ratio=0.15)  # not the default tissue: the response is this actor's
SESSION = [("platform:6", "smile"), ("platform:9", "jaw_open"), ("platform:11", "brow_raise"), ("walk", "pucker"), ("jump", "frown"),
           ("turn", "smile"), ("dance", "jaw_open")]
INNER = slice(10, -10)


@pytest.fixture(scope="module")
def rig():
    return default_face(8)


@pytest.fixture(scope="module")
def session(rig):
    """The actor's calibration session: one held expression per take, under platforms and gaits."""
    return [simulate_take(rig, TakeSpec(f"cal_{k}", motion, expression, duration_s=3.0, seed=300 + k, tissue=TISSUE))
            for k, (motion, expression) in enumerate(SESSION)]


@pytest.fixture(scope="module")
def template(rig, session):
    """A synthesis model to take the setup from (samples, landmarks, stretch, skull input); one epoch."""
    face = FaceSetup.build(rig.topology, rig.neutral, rigid_weights=rig.rigid_weights, face_vertices=rig.face_vertices, sample_count=48)
    takes = [as_take(s) for s in session[:2]]
    truth = {s.spec.name: s.quasistatic for s in session[:2]}
    return train_synthesis(takes, face, rig.uvs, truth, synthesis_config(epochs=1, validation=()), backend="numpy")


@pytest.fixture(scope="module")
def response(session, template):
    """The actor's response fitted on its session, the ridge chosen by the session."""
    return fit_linear_response(template, [as_take(s) for s in session])


def as_take(sim):
    return TrainingSequence(sim.spec.name, sim.captured, FPS, sim.skull_translate, sim.skull_orient)


def rms(values) -> float:
    return float(np.sqrt(np.mean(np.square(values, dtype=np.float64))))


@pytest.mark.slow  # simulates a calibration session of 3 s takes and fits the response on it
def test_held_expressions_give_the_response_that_the_true_dynamics_give(rig, session, template, response):
    """Without truth (each take's held shape and its sag that turns with the head projected
    out), the fit predicts a new motion with a changing expression as well as the same fit (its
    ridge given) on the true dynamics, and far better than nothing."""
    on_truth = fit_linear_response(template, [TrainingSequence(s.spec.name, s.quasistatic[0] + s.offsets, FPS, s.skull_translate, s.skull_orient)
                                              for s in session], ridge=response.info["calibration"]["ridge"])
    new = simulate_take(rig, TakeSpec("speech_run", "run", duration_s=2.0, seed=777, speech=True, tissue=TISSUE))

    def error(model):
        _, offsets = synthesize_dynamics(new.quasistatic, new.skull_translate, new.skull_orient, FPS, model, "numpy")
        return rms(offsets[INNER] - new.offsets[INNER]) / rms(new.offsets[INNER])

    truth_free, upper = error(response), error(on_truth)
    print(f"\nrunning with speech: {truth_free:.3f} of its dynamics left (the fit on true dynamics: {upper:.3f})")
    assert truth_free < 0.5
    assert truth_free < upper + 0.05
    left = response.info["calibration"]["session_cross_validated_left"]
    print(f"the session's motion left by the response fitted without each take: {left:.3f}")
    assert 0 < left < 0.7  # measured 0.48: 3 s takes, each motion seen once


@pytest.mark.slow  # simulates a calibration session of 3 s takes and fits the response on it
def test_the_session_chooses_how_hard_the_response_is_penalized(session, template, response):
    """Each candidate ridge is cross-validated on the session and the one leaving the least of
    the left-out takes' motion is kept: a session tracked with far more noise asks for a
    harder penalty than the clean one; a ridge given is used as given."""
    record = response.info["calibration"]
    assert sorted(map(float, record["ridge_candidates"])) == sorted(RIDGES)
    assert record["session_cross_validated_left"] == min(record["ridge_candidates"].values())
    assert record["temporal_kernels"] == 4  # the modal form's, recorded with the fit
    rng = np.random.default_rng(5)
    noisy = [TrainingSequence(s.spec.name, s.captured + rng.normal(0, 0.3, s.captured.shape).astype(np.float32), FPS,
                              s.skull_translate, s.skull_orient) for s in session]
    harder = fit_linear_response(template, noisy).info["calibration"]
    print(f"\nridge chosen: {record['ridge']} clean, {harder['ridge']} with 3 mm of tracking noise ({harder['ridge_candidates']})")
    assert harder["ridge"] > record["ridge"]
    given = fit_linear_response(template, [as_take(s) for s in session[:2]], ridge=0.5).info["calibration"]  # two takes would choose
    assert given["ridge"] == 0.5 and list(given["ridge_candidates"]) == ["0.5"]
    with pytest.raises(ValueError, match="ridge must be positive"):
        fit_linear_response(template, [as_take(session[0])], ridge=0.0)


@pytest.mark.slow  # simulates a calibration session of 3 s takes and fits the response on it
def test_motion_left_beyond_sag_is_what_a_removal_leaves_of_held_takes(session):
    """On held takes the true quasistatic skin is the held shape plus a sag that follows the
    head, so the true removal leaves nothing, no removal leaves everything, half of it half."""
    from facedyn.dynamics.diagnostics import motion_left_beyond_sag
    from facedyn.geometry import quaternion

    settled = slice(48, None)
    motion = [s.captured[settled].reshape(len(s.captured[settled]), -1) for s in session]
    rotations = [quaternion.to_matrix(s.skull_orient[settled]).reshape(-1, 9) for s in session]

    def left(removed):
        return motion_left_beyond_sag([m - r for m, r in zip(motion, removed)], motion, rotations)

    offsets = [s.offsets[settled].reshape(len(m), -1) for s, m in zip(session, motion)]
    assert left(offsets) < 0.02
    assert left([0 * o for o in offsets]) == pytest.approx(1.0)
    assert left([0.5 * o for o in offsets]) == pytest.approx(0.5, abs=0.02)


@pytest.mark.slow  # simulates a calibration session of 3 s takes and fits the response on it
def test_the_response_is_zero_at_rest_and_survives_the_model_file(rig, session, template, response, tmp_path):
    path = tmp_path / "actor.synthesis"
    save_model(response, path)
    loaded = load_model(path)
    sim = session[3]
    _, saved = synthesize_dynamics(sim.quasistatic, sim.skull_translate, sim.skull_orient, FPS, response, "numpy")
    _, reread = synthesize_dynamics(sim.quasistatic, sim.skull_translate, sim.skull_orient, FPS, loaded, "numpy")
    np.testing.assert_allclose(reread, saved, atol=1e-6)
    tilted = np.repeat(sim.skull_orient[40:41], len(sim.skull_orient), 0)  # a head held still, turned, its face held
    held = np.repeat(sim.quasistatic[40:41], len(tilted), 0)
    _, still = synthesize_dynamics(held, np.repeat(sim.skull_translate[40:41], len(tilted), 0), tilted, FPS, loaded, "numpy")
    assert np.abs(still).max() < 1e-6
    assert np.array_equal(loaded.face.samples, template.face.samples) and loaded.skull_input == template.skull_input
    assert loaded.network.spec.hidden == () and loaded.info["calibration"]["response"] == "linear"
    assert loaded.info["calibration"]["session_cross_validated_left"] == response.info["calibration"]["session_cross_validated_left"]
    assert [t["name"] for t in loaded.info["calibration"]["takes"]] == [s.spec.name for s in session]


@pytest.mark.slow  # simulates a calibration session of 3 s takes and fits the response on it
def test_refusals_name_the_problem(session, template):
    with pytest.raises(ValueError, match="needs a synthesis model"):
        removal = DynamicsModel(kind="removal", network=Network(removal_spec(315, 63)), face=template.face, fps=FPS,
                                windows={"skull": 10, "skin": 10, "target": 10})
        fit_linear_response(removal, [as_take(session[0])])
    short = session[0]
    with pytest.raises(ValueError, match="take 'short' has 60 frames"):
        fit_linear_response(template, [TrainingSequence("short", short.captured[:60], FPS, short.skull_translate[:60], short.skull_orient[:60])])
    with pytest.raises(ValueError, match="at least one take"):
        fit_linear_response(template, [])
    still = TrainingSequence("still", short.captured, FPS, np.repeat(short.skull_translate[:1], len(short.captured), axis=0),
                             np.repeat(short.skull_orient[:1], len(short.captured), axis=0))
    with pytest.raises(ValueError, match=r"takes \['still'\] hold no skull motion"):  # was numpy's "Singular matrix"
        fit_linear_response(template, [still])


def test_skin_the_motion_does_not_move_gives_a_zero_response(session, template):
    """Held expressions that the skull's motion leaves exactly still: a response of zero, not a singular solve."""
    takes = [TrainingSequence(s.spec.name, np.repeat(s.captured[:1], len(s.captured), axis=0), FPS, s.skull_translate, s.skull_orient)
             for s in session[:2]]
    model = fit_linear_response(template, takes, ridge=0.1)
    assert not np.any(model.weights.layers()[0][0])


@pytest.mark.slow  # simulates a calibration session of 3 s takes and fits the response on it
def test_the_translation_kernel_is_the_response_to_an_acceleration_impulse(rig, session, template, response):
    """translation_kernel reads, from the response's weights, what synthesis gives for a skull
    that takes one unit acceleration impulse along each axis: the load a moving expression
    puts on its own tissue."""
    from facedyn.dynamics.expression_inertia import translation_kernel
    from facedyn.dynamics.response import _raw_weights

    past, future = response.skull_input.past, response.skull_input.future
    kernel = translation_kernel(_raw_weights(response), len(response.face.landmarks), past, future)
    frames, impulse = 3 * (past + future + 1), past + future + 1
    still = np.repeat(rig.neutral[None], frames, 0)
    for axis in range(3):
        translate = np.zeros((frames, 3))
        translate[:, axis] = np.maximum(0, np.arange(frames) - impulse) / FPS ** 2  # a second difference of 1 cm/s^2 at `impulse`
        _, offsets = synthesize_dynamics(still, translate, np.tile([1.0, 0, 0, 0], (frames, 1)), FPS, response, "numpy")
        expected = np.empty((len(kernel), rig.neutral.shape[0], 3), np.float32)
        response.propagator().apply_into(np.ascontiguousarray(kernel[..., axis], dtype=np.float32), expected)
        np.testing.assert_allclose(offsets[impulse - future: impulse + past + 1], expected, atol=1e-6 * np.abs(expected).max())
        assert np.abs(offsets[impulse + past + 1:]).max() < 1e-6 * np.abs(expected).max()


@pytest.mark.slow  # simulates a calibration session of 3 s takes and fits the response on it
def test_the_response_removes_the_expression_s_own_inertia(rig, session, template, response):
    """Tissue loaded by its own expression's acceleration (facedyn.sim.tissue with
    expression_inertia 1; the session holds its expressions, so the fit never saw that load):
    with the head still the response's skull term removes nothing and its expression term
    part of the jiggle (measured: 0.91 left; 0.87 before the response's modal form), under a
    walk the term leaves less than the skull alone. A response file from before the term (no
    expression_inertia_hz) removes as it did: what synthesis gives from the skull."""
    import copy

    from facedyn.dynamics.response import remove_with_response

    skull_only = copy.copy(response)
    skull_only.info = copy.deepcopy(response.info)
    del skull_only.info["calibration"]["expression_inertia_hz"]
    assert response.info["calibration"]["expression_inertia_hz"] == 5.0
    loaded = TissueParams(soft_hz=6.5, damping_ratio=0.15, expression_inertia=1.0)
    for motion, most, gain in (("still", 0.95, 0.05), ("walk", 0.5, 0.03)):
        sim = simulate_take(rig, TakeSpec(f"speech_{motion}", motion, duration_s=2.0, seed=778, speech=True, tissue=loaded))
        left = {}
        for name, model in (("with", response), ("skull alone", skull_only)):
            _, offsets = remove_with_response(sim.captured, sim.skull_translate, sim.skull_orient, FPS, model)
            left[name] = rms(offsets[INNER] - sim.offsets[INNER]) / rms(sim.offsets[INNER])
        print(f"\n{motion} with speech, tissue loaded by its expression: left {left}")
        assert left["with"] < most and left["with"] < left["skull alone"] - gain
    _, offsets = remove_with_response(sim.captured, sim.skull_translate, sim.skull_orient, FPS, skull_only)
    _, synthesized = synthesize_dynamics(sim.quasistatic, sim.skull_translate, sim.skull_orient, FPS, skull_only, "numpy")
    np.testing.assert_allclose(offsets, synthesized, atol=1e-6)


@pytest.mark.slow  # simulates a calibration session of 3 s takes and fits the response on it
def test_the_response_synthesizes_the_expression_s_own_inertia(rig, response):
    """Synthesis answers the quasistatic skin's own acceleration as removal answers the
    capture's: on tissue loaded by its expression, with the head still, the response predicts
    part of a talking face's jiggle from its true quasistatic shapes (the skull alone predicts
    none), and what the response removes from a walking capture, synthesized again from the
    quasistatic it leaves on the same skull, comes back closer than the skull alone gives it."""
    import copy

    from facedyn.dynamics.response import remove_with_response

    skull_only = copy.copy(response)
    skull_only.info = copy.deepcopy(response.info)
    del skull_only.info["calibration"]["expression_inertia_hz"]
    loaded = TissueParams(soft_hz=6.5, damping_ratio=0.15, expression_inertia=1.0)
    still = simulate_take(rig, TakeSpec("speech_still", "still", duration_s=2.0, seed=778, speech=True, tissue=loaded))
    walk = simulate_take(rig, TakeSpec("speech_walk", "walk", duration_s=2.0, seed=778, speech=True, tissue=loaded))
    quasistatic, removed = remove_with_response(walk.captured, walk.skull_translate, walk.skull_orient, FPS, response)
    left, round_trip = {}, {}
    for name, model in (("with", response), ("skull alone", skull_only)):
        _, offsets = synthesize_dynamics(still.quasistatic, still.skull_translate, still.skull_orient, FPS, model, "numpy")
        left[name] = rms(offsets[INNER] - still.offsets[INNER]) / rms(still.offsets[INNER])
        _, synthesized = synthesize_dynamics(quasistatic, walk.skull_translate, walk.skull_orient, FPS, model, "numpy")
        round_trip[name] = rms(synthesized[INNER] - removed[INNER]) / rms(removed[INNER])
    print(f"\nstill head with speech, synthesized from the true quasistatic: left {left}; removed, then synthesized: {round_trip}")
    assert left["skull alone"] == pytest.approx(1.0, abs=1e-6)
    assert left["with"] < 0.95
    assert round_trip["with"] < round_trip["skull alone"] - 0.05


@pytest.mark.slow  # simulates a calibration session of 3 s takes and fits the response on it
@pytest.mark.parametrize("stiffening", [5.0, 0.0])
def test_the_response_carries_the_tissue_s_stiffening(rig, template, stiffening, monkeypatch):
    """On tissue of the other simulator family that stiffens with strain, the session's fit
    with its stiffening term answers a new, larger motion (a hop) better than the linear fit
    alone; on the same tissue without stiffening the term stays out of the way."""
    from facedyn.dynamics import hardening
    from facedyn.sim.volumetric import VolumetricParams

    tissue = VolumetricParams(soft_hz=6.0, thickness_cm=1.3, nonlinearity=stiffening, damping_ratio=0.15, substeps=2)
    motions = [("platform:6", "smile"), ("platform:9", "jaw_open"), ("walk", "pucker"), ("jump", "frown"), ("dance", "jaw_open"),
               ("turn", "smile")]
    takes = [as_take(simulate_take(rig, TakeSpec(f"cal_{k}", motion, expression, duration_s=3.0, seed=300 + k, tissue=tissue, impacts=True)))
             for k, (motion, expression) in enumerate(motions)]
    hop = simulate_take(rig, TakeSpec("hop", "hop", duration_s=2.0, seed=777, speech=True, tissue=tissue, impacts=True))
    settled = slice(48, -11)

    def left(model):
        _, offsets = synthesize_dynamics(hop.quasistatic, hop.skull_translate, hop.skull_orient, FPS, model, "numpy")
        return rms(offsets[settled] - hop.offsets[settled]) / rms(hop.offsets[settled])

    stiffened = fit_linear_response(template, takes, ridge=RIDGE)  # one ridge for both: the stiffening alone compared
    monkeypatch.setattr(hardening, "ROUNDS", 0)
    linear = fit_linear_response(template, takes, ridge=RIDGE)
    beta = stiffened.info["calibration"]["hardening"]
    print(f"\nnonlinearity {stiffening}: hop left {left(linear):.3f} linear, {left(stiffened):.3f} with the stiffening (beta {beta:.0f})")
    assert linear.info["calibration"]["hardening"] == 0.0
    if stiffening:
        assert beta > 0
        assert left(stiffened) < left(linear) - 0.002  # measured 0.520 -> 0.516 (free weights before the modal form: 0.554 -> 0.524)
    else:
        assert abs(left(stiffened) - left(linear)) < 0.005  # measured 0.282 / 0.283


@pytest.mark.slow  # simulates a calibration session of 3 s takes and fits the response on it
def test_a_damaged_stiffening_record_is_a_clear_error(session, response):
    import copy

    damaged = copy.copy(response)
    for value in ("stiff", -1.0, float("nan")):
        damaged.info = {**response.info, "calibration": {**response.info["calibration"], "hardening": value}}
        sim = session[0]
        with pytest.raises(ValueError, match="calibration.hardening must be a non-negative number"):
            synthesize_dynamics(sim.quasistatic, sim.skull_translate, sim.skull_orient, FPS, damaged, "numpy")


def test_the_modal_form_recovers_a_response_of_that_form_and_its_kernel_count():
    """Weights that are TEMPORAL_KERNELS time courses over the skull window, each with its own
    map from the skull channels to the samples, come back from their features and targets;
    and whatever the targets, the fit has at most that many time courses."""
    from facedyn.dynamics.response import TEMPORAL_KERNELS, _modal_fit

    rng = np.random.default_rng(4)
    landmarks, width, outputs, rows = 3, 9, 12, 3000
    lag = np.arange(width)
    kernels = np.stack([np.exp(-lag / (2.0 + r)) * np.cos(lag * (0.4 + 0.3 * r)) for r in range(TEMPORAL_KERNELS)], axis=1)
    maps = rng.standard_normal((TEMPORAL_KERNELS, 3 * landmarks, outputs))
    true = np.moveaxis(np.einsum("kr,rco->kco", kernels, maps).reshape(width, landmarks, 3, outputs), 0, 1).reshape(-1, outputs)
    features = rng.standard_normal((rows, landmarks * width * 3))
    targets = features @ true
    gram, moments = features.T @ features, features.T @ targets
    full = np.linalg.solve(gram + 1e-6 * rows * np.eye(len(gram)), moments)
    fitted = _modal_fit(gram, moments, full, 1e-6 * rows, landmarks, width)
    assert np.linalg.norm(fitted - true) / np.linalg.norm(true) < 1e-3

    noise = rng.standard_normal(targets.shape)
    moments = features.T @ noise
    full = np.linalg.solve(gram + rows * np.eye(len(gram)), moments)
    fitted = _modal_fit(gram, moments, full, rows, landmarks, width)
    by_lag = np.moveaxis(fitted.reshape(landmarks, width, 3, outputs), 1, 0).reshape(width, -1)
    singular = np.linalg.svd(by_lag, compute_uv=False)
    assert singular[TEMPORAL_KERNELS] < 1e-9 * singular[0] < singular[TEMPORAL_KERNELS - 1]


def test_the_modal_form_holds_on_an_exactly_rigid_skull():
    """A clean skull track moves the landmarks rigidly: at each lag their accelerations span
    fewer directions than the channels, and the Gram matrix is singular but for the ridge. Fitted
    there on targets as noisy as a session's (expression, tracker), the response predicts the
    true answer as well as the plain ridge fit does (a kernel step without the ridge's share blew
    up into the empty directions and the fit collapsed: it missed 51 % of the true answer here,
    the ridge fit 5 %)."""
    from facedyn.dynamics.features import span_windows
    from facedyn.dynamics.response import TEMPORAL_KERNELS, _modal_fit

    rng = np.random.default_rng(7)
    landmarks, past, future, outputs, rows = 4, 12, 3, 10, 2000
    width = past + future + 1
    motion = np.cumsum(np.cumsum(rng.standard_normal((rows, 6)), axis=0), axis=0)  # six rigid degrees of freedom, smooth
    channels = (motion @ rng.standard_normal((6, 3 * landmarks))).reshape(rows, landmarks, 3)  # 12 channels, rank 6
    features = span_windows(channels, past, future).reshape(rows, -1)
    lag = np.arange(width)
    kernels = np.stack([np.exp(-lag / (2.0 + r)) * np.cos(lag * (0.4 + 0.3 * r)) for r in range(TEMPORAL_KERNELS)], axis=1)
    maps = rng.standard_normal((TEMPORAL_KERNELS, 3 * landmarks, outputs))
    true = np.moveaxis(np.einsum("kr,rco->kco", kernels, maps).reshape(width, landmarks, 3, outputs), 0, 1).reshape(-1, outputs)
    answer = features @ true
    targets = answer + answer.std() * rng.standard_normal(answer.shape)
    scaled = features / features.std(axis=0)
    gram, moments = scaled.T @ scaled, scaled.T @ targets
    penalty = 1e-2 * rows
    full = np.linalg.solve(gram + penalty * np.eye(len(gram)), moments)
    fitted = _modal_fit(gram, moments, full, penalty, landmarks, width)

    def missed(weights):
        return np.linalg.norm(scaled @ weights - answer) / np.linalg.norm(answer)

    assert np.linalg.matrix_rank(gram, tol=1e-9 * np.trace(gram)) < len(gram)
    assert missed(full) < 0.1
    assert missed(fitted) < missed(full) + 0.02


def test_the_response_is_its_own_kind_and_old_synthesis_files_load_as_one(template, response, tmp_path):
    """A response is kind "response" (`is_linear_response` reads the kind); a file written when
    responses were synthesis models calibrated `response: linear` loads as a response, and H
    stays H."""
    import dataclasses

    from facedyn.dynamics.modelfile import describe_model
    from facedyn.dynamics.response import is_linear_response

    assert response.kind == "response" and is_linear_response(response) and not is_linear_response(template)
    old = tmp_path / "actor.synthesis"
    save_model(dataclasses.replace(response, kind="synthesis"), old)
    loaded = load_model(old)
    assert loaded.kind == "response" and is_linear_response(loaded)
    assert load_model(save_model(template, tmp_path / "h.synthesis")).kind == "synthesis"
    described = describe_model(old)
    assert described["network"] == "linear response (actor's)" and described["calibration"]["ridge"] == response.info["calibration"]["ridge"]


def test_a_blend_holds_its_members_whole_in_one_checked_file(template, response, tmp_path):
    """save_blend writes the members (removal models, responses) into one file: load_models
    gives them back as saved, load_model refuses it (only removal reads a blend), a network H
    is no member, and a changed byte is caught by the file's checksums."""
    from facedyn.dynamics.modelfile import ModelFileError, describe_model, load_models, save_blend

    from facedyn.dynamics.bands import BandWeights

    path = save_blend([response, response], tmp_path / "removal.blend")
    members, weights = load_models(path, topology=response.fingerprint, fps=FPS)
    assert [m.kind for m in members] == ["response", "response"] and weights.is_mean()
    for member in members:
        for ours, theirs in zip(member.weights.state.values(), response.weights.state.values()):
            assert np.array_equal(ours, theirs)
        assert member.info["calibration"] == response.info["calibration"]
    assert [m.kind for m in load_models(save_model(response, tmp_path / "one.response"))[0]] == ["response"]
    bands = BandWeights((2.0, 4.0), np.array([[0.25, 0.75], [0.5, 0.5], [1.0, 0.0]]))
    banded = save_blend([response, response], tmp_path / "bands.blend", bands)
    assert load_models(banded)[1].to_json() == bands.to_json()
    assert describe_model(banded)["bands"] == bands.to_json() and "per frequency band" in describe_model(banded)["network"]
    assert "bands" not in describe_model(path) and describe_model(path)["network"].startswith("the mean of")
    with pytest.raises(ModelFileError, match="a blend of 2 removal models"):
        load_model(path)
    assert describe_model(path)["kind"] == "blend" and len(describe_model(path)["members"]) == 2
    with pytest.raises(ValueError, match="a blend holds two or more removal models or linear responses"):
        save_blend([response, template], tmp_path / "bad.blend")
    damaged = bytearray(path.read_bytes())
    damaged[-5] ^= 0xFF
    (tmp_path / "damaged.blend").write_bytes(bytes(damaged))
    with pytest.raises(ModelFileError, match="checksum"):
        load_models(tmp_path / "damaged.blend")


def test_leaving_a_take_out_downdates_the_normal_equations_to_the_refit(session, template):
    """Each left-out fit is the session's normal equations less the take's own: the same
    weights, to rounding, as summing the other takes' afresh and solving (the session's
    stiffening and the targets it leaves kept), and so the same left-out figure."""
    from facedyn.dynamics import response as r
    from facedyn.dynamics.diagnostics import motion_left_beyond_sag

    rows = [r._take_rows(as_take(s), template, r.SETTLE_S) for s in session]
    sums = r._Sums.total(rows)
    fit = r._session_fit(rows, sums, 0.1, template)
    downdated = list(r._fits_without_each(rows, sums, 0.1, fit, template))
    targets = fit[2]
    refits = []
    for k in range(len(rows)):
        others = [x for j, x in enumerate(rows) if j != k]
        solve = r._solver(r._Sums.total(others), 0.1, len(template.face.landmarks), template.skull_input.width)
        refits.append((*solve(*r._moments(others, [t for j, t in enumerate(targets) if j != k])), fit[1]))
    for (w, scale, beta), (w_ref, scale_ref, beta_ref) in zip(downdated, refits):
        np.testing.assert_allclose(scale, scale_ref, rtol=1e-10)
        # the modal form's alternations carry the sums' rounding along: a few parts in 1e9 of the largest weight
        np.testing.assert_allclose(w, w_ref, rtol=1e-6, atol=1e-7 * np.abs(w_ref).max())
        assert beta == beta_ref
    whole = [x.targets for x in rows]
    figures = [motion_left_beyond_sag([x.targets - r._predict(x, f, template) for x, f in zip(rows, fits)], whole, [x.rotations for x in rows])
               for fits in (downdated, refits)]
    assert figures[0] == pytest.approx(figures[1], rel=1e-7)
    assert r.cross_validated_left(rows, 0.1, template) == pytest.approx(figures[0], rel=1e-12)
