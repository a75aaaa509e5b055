"""Stabilization of plain captures: rigidity discovered from the data, tracker errors,
dropped frames, and an actor's prior (facedyn.stabilize.rigidity, dropped, api)."""
import numpy as np
import pytest

from facedyn.evaluation import implied_skull_transforms, skull_frame_disagreement, stabilization_errors
from facedyn.sim.corpus import TakeSpec, simulate_take
from facedyn.sim.default_face import default_face
from facedyn.sim.noise import TrackerNoise, add_tracker_noise
from facedyn.stabilize import Schedule, stabilize
from facedyn.stabilize.dropped import bridge_dropped, tracked_frames
from facedyn.stabilize.inertia import check_frame
from facedyn.stabilize.rigidity import RigidModel, discover_rigid_mode, estimate_rigidity
from facedyn.stabilize.synthetic import synthetic_take

TRACKER = TrackerNoise(iid_cm=0.01, temporal_cm=0.004, spatial_cm=0.002)


@pytest.fixture(scope="module")
def rig():
    return default_face()


def capture(rig, spec, noise=TRACKER):
    """A simulated take's truth and its tracked points with the tracker's errors."""
    take = simulate_take(rig, spec)
    tracked = add_tracker_noise(take.world_points(), spec.fps, noise, rig.neutral, seed=spec.seed)
    return take, tracked


@pytest.fixture(scope="module")
def talking(rig):
    """Speech-like expressions (jaw, smile, pucker changing) under walking, 2 s at 120 fps."""
    spec = TakeSpec("talk", "walk", "jaw_open", duration_s=2.0, seed=3)
    take = simulate_take(rig, spec)
    # make the expression change all the time, not only ease in: replay the held jaw as a 2 Hz open-close
    phase = 0.5 - 0.5 * np.cos(2 * np.pi * 2.0 * np.arange(len(take.frames)) / spec.fps)
    neutral = rig.neutral[None]
    take.quasistatic = (neutral + phase[:, None, None] * (take.quasistatic - neutral)).astype(np.float32)
    take.captured = take.quasistatic + take.offsets
    tracked = add_tracker_noise(take.world_points(), spec.fps, TRACKER, rig.neutral, seed=4)
    return take, tracked


def errors(rig, take, result):
    return stabilization_errors(result.translate, result.orient, take.skull_translate, take.skull_orient,
                                take.quasistatic + take.offsets, rig.face_vertices)


@pytest.mark.slow  # simulates talking takes and stabilizes them several ways
def test_discovered_weights_separate_bone_from_soft_tissue(rig, talking):
    take, tracked = talking
    model = estimate_rigidity(tracked.points)
    bone, soft = rig.rigid_weights == 1, rig.rigid_weights < 0.5
    assert model.weights[bone].mean() > 0.9
    assert model.weights[soft].mean() < 0.02
    assert model.noise_cm == pytest.approx(2.5 * np.sqrt(0.01**2 + 0.004**2 + 0.002**2), rel=0.3)  # 90 % of |3D normal|


@pytest.mark.slow  # simulates talking takes and stabilizes them several ways
def test_no_mask_stabilization_beats_the_old_default_and_nears_the_oracle(rig, talking):
    take, tracked = talking
    world = tracked.points
    discovered = errors(rig, take, stabilize(world, take.fps))
    every_vertex = errors(rig, take, stabilize(world, take.fps, weights=np.ones(rig.point_count)))  # the old default
    oracle = errors(rig, take, stabilize(world, take.fps, method="procrustes", rest=rig.neutral,
                                          weights=(rig.rigid_weights == 1).astype(float)))
    assert discovered["median_vertex_cm"] < 0.2 * every_vertex["median_vertex_cm"]
    assert discovered["median_vertex_cm"] <= 1.5 * oracle["median_vertex_cm"]
    assert discovered["mean_vertex_cm"] <= 1.5 * oracle["mean_vertex_cm"]


@pytest.mark.slow  # simulates takes and stabilizes them
def test_pops_and_dropped_frames_do_not_move_the_skull(rig):
    spec = TakeSpec("smile", "walk", "smile", duration_s=1.5, seed=9)
    clean_take, clean = capture(rig, spec)
    _, rough = capture(rig, spec, TrackerNoise(iid_cm=0.01, temporal_cm=0.004, spatial_cm=0.002,
                                               pop_rate=4.0, pop_cm=0.5, drop_rate=0.03))
    assert rough.popped.any() and (~rough.valid).sum() == 5
    base = errors(rig, clean_take, stabilize(clean.points, spec.fps))
    result = stabilize(rough.points, spec.fps)
    np.testing.assert_array_equal(result.tracked, rough.valid)  # repeated frames found on their own
    hit = errors(rig, clean_take, result)
    assert hit["median_vertex_cm"] < 1.5 * base["median_vertex_cm"] + 5e-4
    assert hit["max_rotation_deg"] < 0.1


def test_nan_frames_count_as_dropped_but_partial_nan_is_an_error(rig):
    f = np.arange(8.0)[:, None, None]
    coefficients = np.random.default_rng(0).normal(size=(4, 10, 3))
    world = sum(c * f**k for k, c in enumerate(coefficients))  # cubic in time: bridged exactly
    holes = world.copy()
    holes[3] = np.nan
    tracked = tracked_frames(holes, np.array([1, 1, 1, 1, 1, 0, 1, 1], bool))
    np.testing.assert_array_equal(tracked, [1, 1, 1, 0, 1, 0, 1, 1])
    np.testing.assert_allclose(bridge_dropped(holes, tracked), world, atol=1e-9)
    bad = world.copy()
    bad[3, 4, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        stabilize(bad, 120.0)


@pytest.mark.slow  # simulates takes and stabilizes them
def test_a_prior_puts_two_takes_in_one_skull_frame(rig):
    first, tracked_first = capture(rig, TakeSpec("brows", "walk", "brow_raise", duration_s=1.0, seed=21))
    actor = stabilize(tracked_first.points, 120.0).model
    frames, alone = [], []
    for seed, motion in ((22, "walk"), (23, "run")):
        take, tracked = capture(rig, TakeSpec(f"smile_{motion}", motion, "smile", duration_s=1.0, seed=seed))
        result = stabilize(tracked.points, take.fps, prior=actor)
        np.testing.assert_allclose(result.rest, actor.rest)  # solved in the actor's skull frame
        assert np.all(result.model.weights <= actor.weights)
        frames.append(implied_skull_transforms(result.translate, result.orient, take.skull_translate,
                                               take.skull_orient, take.quasistatic + take.offsets, rig.face_vertices)[2])
        alone.append(stabilize(tracked.points, take.fps).rest)
    assert skull_frame_disagreement(frames[0], frames[1], rig.neutral[rig.face_vertices]) <= 0.005
    # without the prior each take has its own frame (near its own first frame's pose)
    assert np.median(np.linalg.norm(alone[0] - alone[1], axis=1)) > 0.05


def test_rigid_models_merge_and_check_their_shapes():
    n = 5
    a = RigidModel(np.ones(n), np.zeros((n, 3)), np.full(n, 0.02), 0.02)
    b = RigidModel(np.array([1, 1, 1, 0, 0.5]), np.ones((n, 3)), np.full(n, 0.03), 0.03)
    merged = a.merge(b)
    np.testing.assert_allclose(merged.weights, [1, 1, 1, 0, 0.5])
    np.testing.assert_allclose(merged.rest, 0.5)
    assert merged.takes == 2 and merged.noise_cm == 0.03
    with pytest.raises(ValueError, match="weights"):
        RigidModel(np.full(n, 2.0), np.zeros((n, 3)), np.zeros(n), 0.0)
    with pytest.raises(ValueError, match="prior rigid model has 5 vertices"):
        stabilize(np.zeros((4, 7, 3)), 120.0, prior=a)


@pytest.mark.slow  # the simulator's correlated tracker noise over the whole face, three times
def test_tracker_noise_components_are_seeded_and_shaped(rig):
    points = np.repeat(rig.neutral[None], 240, axis=0)
    noise = TrackerNoise(temporal_cm=0.01, correlation_s=0.25)
    out = add_tracker_noise(points, 120.0, noise, rig.neutral, seed=1).points - points
    assert out.std() == pytest.approx(0.01, rel=0.1)
    lag = np.corrcoef(out[:-12].ravel(), out[12:].ravel())[0, 1]  # 0.1 s apart: still correlated
    assert lag > 0.8
    spatial = add_tracker_noise(points, 120.0, TrackerNoise(spatial_cm=0.01), rig.neutral, seed=1).points - points
    near = np.argsort(np.linalg.norm(rig.neutral - rig.neutral[0], axis=1))[1]
    assert np.corrcoef(spatial[:, 0].ravel(), spatial[:, near].ravel())[0, 1] > 0.8
    again = add_tracker_noise(points, 120.0, noise, rig.neutral, seed=1).points - points
    np.testing.assert_array_equal(out, again)
    with pytest.raises(ValueError, match="drop_mode"):
        TrackerNoise(drop_mode="hold")


@pytest.mark.slow  # simulates takes and stabilizes them
def test_an_actors_neutral_as_prior_is_still_checked_for_rigidity_per_take(rig, talking):
    """An actor that knows only its neutral (every vertex a candidate): the take keeps the neutral as its rest (the
    actor's skull frame) and its own data rules out the vertices that move (the jaw opening and closing)."""
    take, tracked = talking
    result = stabilize(tracked.points, take.fps, prior=RigidModel.known(rig.neutral))
    np.testing.assert_allclose(result.rest, rig.neutral, atol=1e-6)
    assert result.knot_spacing is not None and result.knot_spacing >= 1 / take.fps  # chosen for the take
    moving = np.linalg.norm(take.quasistatic - rig.neutral, axis=-1).max(axis=0) > 0.1
    assert moving.sum() > 20 and np.all(result.model.weights[moving] == 0)
    oracle = errors(rig, take, stabilize(tracked.points, take.fps, method="procrustes", rest=rig.neutral,
                                          weights=(rig.rigid_weights == 1).astype(float)))
    assert errors(rig, take, result)["median_vertex_cm"] <= 1.5 * oracle["median_vertex_cm"]


def test_a_priors_noise_floor_is_measured_on_its_bone_so_its_sliding_falloff_is_dropped():
    """A rig whose bone is a small part of the mesh (the ICT rig: 8 %): a quantile over every vertex would land on soft
    tissue and keep the prior's falloff ring, skin that slides against the skull, at full weight. Measured on the
    vertices the prior holds fully rigid, the floor is the tracking noise and the ring is dropped."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(7)
    frames, fps = 240, 120.0
    bone, ring, soft = np.arange(0, 40), np.arange(40, 100), np.arange(100, 400)
    rest = rng.normal(scale=6.0, size=(400, 3))
    time = np.arange(frames) / fps
    skull_space = np.repeat(rest[None], frames, axis=0)
    skull_space[:, ring] += 0.3 * np.sin(2 * np.pi * time)[:, None, None] * np.array([0.0, 1.0, 0.0])  # slides as a block
    skull_space[:, soft] += rng.normal(scale=0.5, size=(frames, len(soft), 3))
    turn = Rotation.from_rotvec(0.1 * np.stack([np.sin(3 * time), np.cos(2 * time), np.sin(time)], axis=1))
    world = np.einsum("fij,fnj->fni", turn.as_matrix(), skull_space) + rng.normal(scale=0.01, size=skull_space.shape)
    prior_weights = np.zeros(400)
    prior_weights[bone], prior_weights[ring] = 1.0, 0.5  # a rig's falloff from its bone set
    model = estimate_rigidity(world, RigidModel.known(rest, prior_weights))
    assert np.all(model.weights[ring] == 0) and np.all(model.weights[soft] == 0)
    assert model.weights[bone].mean() > 0.9
    assert model.noise_cm == pytest.approx(2.5 * 0.01, rel=0.3)  # 90 % of |3D normal| at 0.01 cm


def _head_with_a_block(block_on_springs: bool, fps=120.0, seconds=3.0, seed=11):
    """A walking head (translation at 0.9 and 1.8 Hz, a nod): 60 bone vertices, a block of 200 that no expression moves
    (on 8 Hz springs to the bone, or on the bone), 150 soft ones (6 Hz springs and a slow expression). World (F, N, 3)."""
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(seed)
    frames, steps = int(seconds * fps), 20
    t = np.arange(frames * steps) / (fps * steps)
    translate = np.stack([1.0 * np.sin(2 * np.pi * 0.9 * t), 2.0 * np.sin(2 * np.pi * 1.8 * t), 0 * t], axis=1)
    nod = Rotation.from_rotvec(np.radians(3.0) * np.sin(2 * np.pi * 1.8 * t + 0.5)[:, None] * [1.0, 0.0, 0.0])
    acceleration = nod.inv().apply(np.gradient(np.gradient(translate, t, axis=0), t, axis=0))  # in the skull frame

    def lag(hz, damping=0.25):  # tissue on a spring: u'' + 2 zeta w u' + w^2 u = -a
        w, u, v, out = 2 * np.pi * hz, np.zeros(3), np.zeros(3), np.empty_like(acceleration)
        for k, a in enumerate(acceleration):
            v += (-a - 2 * damping * w * v - w * w * u) / (fps * steps)
            u = u + v / (fps * steps)
            out[k] = u
        return out[::steps]

    rest = rng.normal(scale=6.0, size=(410, 3))
    skull = np.repeat(rest[None], frames, axis=0)
    if block_on_springs:
        skull[:, 60:260] += lag(8.0)[:, None]
    expression = 0.5 * np.sin(2 * np.pi * 0.3 * t[::steps])[:, None, None] * rng.normal(size=(1, 150, 3))
    skull[:, 260:] += lag(6.0)[:, None] + expression
    world = nod[::steps].as_matrix() @ skull.transpose(0, 2, 1)
    return world.transpose(0, 2, 1) + translate[::steps, None] + rng.normal(scale=0.01, size=skull.shape)


def test_a_mode_on_a_sliding_block_is_flagged_by_the_energy_the_face_would_feed():
    """facedyn.stabilize.inertia: a block larger and as still as the bone wins rigidity discovery's statistics; in its
    frame the rest of the face moves as if it fed energy into the head's motion, which passive tissue never does."""
    world = _head_with_a_block(True)
    block = estimate_rigidity(world)
    assert block.weights[60:260].mean() > 0.9 and block.weights[:60].max() == 0  # the statistics lock on the block
    solved = stabilize(world, 120.0, rest=block.rest, weights=block.weights, schedule=Schedule.locked())
    check = check_frame(world, solved.translate, solved.orient, block.rest, np.flatnonzero(block.weights == 0), 120.0)
    assert check.suspect and check.feeding > 0.1
    on_bone = stabilize(_head_with_a_block(False), 120.0)
    assert on_bone.model.weights[:260].mean() > 0.9
    assert on_bone.inertia.feeding < 0.02 and on_bone.inertia.absorbing > 0.5


def test_discovery_finds_the_bone_under_a_sliding_block():
    """discover_rigid_mode: when the face feeds energy in the mode found, discovery starts again from what leads it
    most (the bone)."""
    found = stabilize(_head_with_a_block(True), 120.0)
    assert found.model.weights[:60].mean() > 0.95 and found.model.weights[60:].max() == 0.0
    assert found.inertia.feeding < 0.02 and found.inertia.absorbing > 0.5


def test_motion_that_inertia_does_not_explain_feeds_nothing():
    """Expressions that happen to move with the head (a synthetic take without dynamics) are not inertia: nothing
    feeds, and the discovered mode stays the skull's, not a patch of skin the expressions leave alone."""
    take = synthetic_take(frames=180, vertices=400, fps=120.0, seed=3)
    model, check = discover_rigid_mode(take.world, take.fps)
    assert not check.suspect and check.feeding == 0.0
    rigid_found = model.weights >= 1.0
    assert np.count_nonzero(rigid_found) > 100 and not np.any(rigid_found & take.deforming)
