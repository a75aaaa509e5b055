"""The test set's MuJoCo actor generator (benchmarks/testset) on a tiny face patch."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco", reason="the test set's tissue is MuJoCo's flex: pip install mujoco (the dev extra has it)")
BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

from facedyn.performance import Topology  # noqa: E402
from facedyn.rig import FaceRig  # noqa: E402
from testset.generate import Drives, simulate_take, write_take  # noqa: E402
from testset.takes import TakeRecipe  # noqa: E402
from testset.tissue import MujocoTissue, TissueParams  # noqa: E402

FPS, SUBSTEPS = 60.0, 10


def tiny_rig() -> FaceRig:
    """A 9 x 9 curved patch facing +Z (cm) with a bump (a 'nose') and one shape pulling its lower half down."""
    x, y = np.meshgrid(np.linspace(-4, 4, 9), np.linspace(-4, 4, 9))
    z = 10 - (x ** 2 + y ** 2) / 16 + 1.5 * np.exp(-(x ** 2 + y ** 2) / 3)
    neutral = np.stack([x, y, z], -1).reshape(-1, 3)
    quads = [(j * 9 + i, j * 9 + i + 1, (j + 1) * 9 + i + 1, (j + 1) * 9 + i) for j in range(8) for i in range(8)]
    topology = Topology(np.full(len(quads), 4, np.int32), np.asarray(quads, np.int32).ravel())
    jaw = np.zeros_like(neutral)
    jaw[:, 1] = -0.5 * np.clip(-neutral[:, 1] / 4, 0, 1)
    return FaceRig("tiny", neutral, topology, expression_names=("jawOpen",), expression_offsets=jaw[None])


@pytest.fixture(scope="module")
def tissue():
    rig = tiny_rig()
    return rig, MujocoTissue(rig.neutral, rig.topology.triangles(), rig.face_vertices, TissueParams(), 1 / (FPS * SUBSTEPS))


def still_drives(tissue_, rig, steps, translate=None):
    translate = np.zeros((steps, 3)) if translate is None else translate
    orient = np.tile([1.0, 0, 0, 0], (steps, 1))
    return Drives(tissue_, rig, translate, orient, np.zeros((steps, rig.expression_count)))


def test_shell_is_a_valid_tetrahedral_layer_with_both_attachments(tissue):
    _, t = tissue
    assert 100 < len(t.shell.tets) < 1000
    assert t.shell.pinned.any() and (~t.shell.pinned).any()  # bone where the patch is flat, a deep 'nose' over it


def test_generation_is_deterministic(tissue):
    rig, t = tissue
    recipe = TakeRecipe("t", "test", "platform:8", expression="jaw_open", duration_s=0.25, seed=3)
    a = simulate_take(rig, t, recipe, Path("."), FPS)
    b = simulate_take(rig, t, recipe, Path("."), FPS)
    for key in ("captured", "quasistatic", "dynamics"):
        np.testing.assert_array_equal(a[key], b[key])
    assert np.abs(a["dynamics"]).max() > 1e-3  # a platform at 8 Hz moves the tissue (cm)


def test_gravity_sags_the_still_face(tissue):
    rig, t = tissue
    skin = t.simulate(still_drives(t, rig, 300), SUBSTEPS)[-1] * 100
    drop = skin[:, 1] - rig.neutral[t.shell.skin, 1]
    assert drop.mean() < -0.01 and drop.max() < 1e-4  # cm: down, nowhere up


def test_a_skull_jolt_rings_down(tissue):
    rig, t = tissue
    steps = 900
    translate = np.zeros((steps, 3))
    ramp = np.clip((np.arange(steps) - 60) / 12.0, 0, 1)  # 1 cm forward in 20 ms, 0.1 s in
    translate[:, 2] = ramp * ramp * (3 - 2 * ramp)
    skin = t.simulate(still_drives(t, rig, steps, translate), 1) * 100
    relative = skin - translate[:, None]  # skull space (no rotation), cm
    settled = relative[-1]
    early = np.abs(relative[80:230] - settled).max()
    late = np.abs(relative[-150:] - settled).max()
    assert early > 0.05 and late < 0.25 * early


def test_pinned_inner_layer_follows_the_bone(tissue):
    rig, t = tissue
    steps = 600
    translate = np.zeros((steps, 3))
    translate[:, 1] = 2.0 * np.sin(2 * np.pi * 1.5 * np.arange(steps) / 600)  # 2 cm at 1.5 Hz, below the tissue's modes
    drives = still_drives(t, rig, steps, translate)
    skin = t.simulate(drives, 1) * 100
    final = drives[steps - 1]
    bone = t.data.qpos[t.dof[t.kinematic]] + t.origin[t.kinematic]
    travel = np.abs(translate[-1] - translate[-2]).max() / 100  # m: the bone's last step
    assert np.abs(bone - (final.targets[: len(t.kinematic)] + final.translation)).max() < 2 * travel
    over_bone = t.shell.pinned & ~t.shell.rim
    lag = np.abs(skin[:, over_bone] - translate[:, None] - (skin[0, over_bone] - translate[0])).max()
    assert 0.001 < lag < 0.3  # cm: the skin over bone moves with it, a little behind

@pytest.mark.slow
def test_written_capture_imports_with_usdfacedyn(tissue, tmp_path):
    from facedyn.usd.take import read_take

    rig, t = tissue
    recipe = TakeRecipe("t", "test", "platform:6", expression="jaw_open", duration_s=0.3, seed=5)
    take = simulate_take(rig, t, recipe, Path("."), FPS)
    write_take(tmp_path / "take", take, rig, seed=1)
    done = subprocess.run([sys.executable, "-m", "facedyn.cli", "import", str(tmp_path / "take" / "tracked.usdc"), "-o",
                           str(tmp_path / "imported" / "capture.usdc"), "-q"], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    performance, _ = read_take(tmp_path / "imported" / "capture.usdc")
    assert performance.fps == 60 and len(performance.points) == len(take["frames"])
    assert np.abs(performance.points - take["world"]).max() < 1.0  # cm: tracker noise and pops only
    truth = np.load(tmp_path / "take" / "truth.npz")
    np.testing.assert_allclose(truth["dynamics"], truth["captured"] - truth["quasistatic"], atol=1e-5)


def test_score_is_the_fraction_of_the_true_dynamics_left():
    from testset.score import fraction_left, moving_average_estimate

    rng = np.random.default_rng(0)
    dynamics = rng.standard_normal((40, 6, 3)).astype(np.float32)
    truth = {"dynamics": dynamics, "face_vertices": np.array([0, 2, 3])}
    assert fraction_left(np.zeros_like(dynamics), truth) == pytest.approx(1.0)
    assert fraction_left(dynamics, truth) == 0.0
    assert fraction_left(dynamics * 0.5, truth) == pytest.approx(0.5, rel=1e-6)
    still = np.repeat(rng.standard_normal((1, 6, 3)), 40, axis=0)
    np.testing.assert_allclose(moving_average_estimate(still, truth), 0.0, atol=1e-9)  # a held shape has no dynamics
    with pytest.raises(ValueError, match="shape"):
        fraction_left(np.zeros((40, 5, 3)), truth)


def test_the_static_share_is_the_floor_of_any_estimate_that_averages_to_zero():
    """static_share: the RMS of the truth's mean over the take over its RMS; an estimate with
    zero mean over the take (here the truth less its mean, the best such) leaves exactly it."""
    from testset.score import fraction_left, static_share

    rng = np.random.default_rng(1)
    ringing = rng.standard_normal((60, 6, 3))
    ringing -= ringing.mean(axis=0)
    offset = np.zeros((6, 3))
    offset[2] = (3.0, 0.0, 0.0)  # one vertex settles 3 units away while the rest ring about rest
    truth = {"dynamics": (ringing + offset).astype(np.float32), "face_vertices": np.array([0, 2, 3])}
    share = static_share(truth)
    expected = np.sqrt(9.0 / 3 / np.mean(np.sum((ringing + offset)[:, [0, 2, 3]] ** 2, axis=-1)))
    assert share == pytest.approx(expected, rel=1e-5) and 0 < share < 1
    assert fraction_left(ringing, truth) == pytest.approx(share, rel=1e-4)
    assert static_share({"dynamics": ringing.astype(np.float32), "face_vertices": np.arange(6)}) < 1e-6


def test_the_moving_part_left_sets_the_static_share_apart():
    from testset.score import fraction_left, moving_left, static_share

    rng = np.random.default_rng(3)
    moving = rng.normal(size=(40, 6, 3))
    moving -= moving.mean(axis=0)
    truth = {"dynamics": moving + np.array([0.0, 0.5, 0.0]), "face_vertices": np.arange(1, 6)}
    settled_elsewhere = moving.copy()  # every motion found, the offset it settled at missed
    assert moving_left(settled_elsewhere, truth) == pytest.approx(0.0, abs=1e-12)
    assert fraction_left(settled_elsewhere, truth) == pytest.approx(static_share(truth), rel=1e-9)
    assert moving_left(np.zeros_like(moving), truth) == pytest.approx(1.0)
    assert moving_left(moving * 0.5, truth) == pytest.approx(0.5, rel=1e-9)


def test_a_faster_mocap_is_the_same_path_in_less_time():
    from testset.takes import LEAD_S, skull_trajectory

    data = BENCHMARKS.parents[1] / "shared" / "data"
    if not (data / "cmu-mocap" / "131_02.bvh").is_file():
        pytest.skip(f"{data}: the shared CMU mocap is not here")
    normal = skull_trajectory(TakeRecipe("a", "test", "bvh:131_02.bvh", duration_s=1.0, seed=4), data, 60.0)
    fast = skull_trajectory(TakeRecipe("b", "test", "bvh:131_02.bvh@1.6", duration_s=1.0, seed=4), data, 60.0)
    assert len(normal.translate) == len(fast.translate) == round((LEAD_S + 1.0) * 60)
    step = lambda t: np.linalg.norm(np.diff(t.translate, axis=0), axis=1).mean()  # noqa: E731
    assert step(fast) == pytest.approx(1.6 * step(normal), rel=0.25)


def test_a_scaled_motion_keeps_its_steady_travel_and_scales_the_rest():
    """testset_static.py's knob: accelerations and turns scaled, the steady path (no load) kept."""
    from facedyn.geometry import quaternion
    from facedyn.performance import SkullTrajectory
    from testset.takes import scaled_about_steady_path

    t = np.arange(120) / 60.0
    translate = np.stack([130.0 * t, 160 + 1.5 * np.sin(2 * np.pi * 2 * t), 0.3 * np.cos(2 * np.pi * 3 * t)], 1)
    orient = quaternion.from_rotvec(np.stack([0.1 * np.sin(2 * np.pi * 2 * t), 0.3 + 0.05 * t, np.zeros_like(t)], 1))
    walk = SkullTrajectory(translate, orient, 60.0)
    half = scaled_about_steady_path(walk, 0.5)
    acceleration = lambda w: np.diff(w.translate, 2, axis=0)  # noqa: E731
    np.testing.assert_allclose(acceleration(half), 0.5 * acceleration(walk), atol=1e-9)
    assert abs(half.translate[:, 0] - translate[:, 0]).max() < 1e-9  # the travel forward is steady: kept
    turn = lambda w: quaternion.to_rotvec(w.orient)  # noqa: E731
    np.testing.assert_allclose(np.ptp(turn(half), axis=0), 0.5 * np.ptp(turn(walk), axis=0), rtol=0.02, atol=1e-12)
    same = scaled_about_steady_path(walk, 1.0)
    np.testing.assert_allclose(same.translate, translate, atol=1e-9)
    np.testing.assert_allclose(np.abs((same.orient * orient).sum(1)), 1.0, atol=1e-9)


def test_the_session_is_held_apart_from_the_test_takes_and_a_transfer_take_is_theirs_crossed():
    """The session (the issue's protocol: ten held expressions on five platforms and under two
    real motions) holds none of the test takes' expression, frequency or mocap, nor their seeds;
    a transfer take plays the walking dialog's expression under exactly the run's skull."""
    from testset.actors import session_takes, test_takes, transfer_takes
    from testset.takes import expression_weights, skull_trajectory

    session, tests, (transfer,) = session_takes(2101), test_takes(2101), transfer_takes(2101)
    assert len(session) == 70 and len({t.name for t in session}) == 70
    assert {t.expression for t in session}.isdisjoint({t.expression for t in tests if t.expression})
    assert not any(t.motion in ("platform:8", "bvh:131_02.bvh") or "131_02" in t.motion for t in session)
    assert {t.seed for t in session}.isdisjoint({t.seed for t in tests} | {transfer.seed, transfer.skull_seed})
    walk, run, _ = tests
    assert transfer.kind == "transfer" and transfer.sources == ("dialog_walk", "dialog_run")
    data = BENCHMARKS.parents[1] / "shared" / "data"
    if not (data / "cmu-mocap" / "131_02.bvh").is_file():
        pytest.skip(f"{data}: the shared CMU mocap is not here")
    crossed, driving = skull_trajectory(transfer, data, 60.0), skull_trajectory(run, data, 60.0)
    np.testing.assert_array_equal(crossed.translate, driving.translate)
    np.testing.assert_array_equal(crossed.orient, driving.orient)
    names = ("jawOpen", "mouthFunnel", "mouthSmile_L")
    np.testing.assert_array_equal(expression_weights(transfer, names, data, 60.0, 90), expression_weights(walk, names, data, 60.0, 90))
    assert not np.array_equal(expression_weights(transfer, names, data, 60.0, 90), expression_weights(run, names, data, 60.0, 90))


def test_a_cross_take_plays_this_actors_walk_under_another_actors_run():
    """The issue's retargeting case: the walking dialog's expression (this actor's seed) under
    exactly the source actor's run skull (its seed); only an actor of the same face can be a source."""
    from testset.actors import ACTORS, cross_actor_takes, test_takes
    from testset.generate import generate_actor
    from testset.takes import expression_weights, skull_trajectory

    target, source = ACTORS["test_default_3103"], ACTORS["val_default_2101"]
    (cross,) = cross_actor_takes(target.take_seed, source)
    walk, _, _ = test_takes(target.take_seed)
    _, their_run, _ = test_takes(source.take_seed)
    assert cross.kind == "cross" and cross.sources == ("dialog_walk", "val_default_2101/dialog_run")
    assert (cross.seed, cross.skull_seed, cross.motion) == (walk.seed, their_run.seed, their_run.motion)
    with pytest.raises(ValueError, match="another actor of the default face"):
        generate_actor(target, Path("/nonexistent/actor"), Path("."), ("cross",), source=ACTORS["val_ict_2102"])
    data = BENCHMARKS.parents[1] / "shared" / "data"
    if not (data / "cmu-mocap" / "131_02.bvh").is_file():
        pytest.skip(f"{data}: the shared CMU mocap is not here")
    crossed, driving = skull_trajectory(cross, data, 60.0), skull_trajectory(their_run, data, 60.0)
    np.testing.assert_array_equal(crossed.orient, driving.orient)
    names = ("jawOpen", "mouthFunnel", "mouthSmile_L")
    np.testing.assert_array_equal(expression_weights(cross, names, data, 60.0, 90), expression_weights(walk, names, data, 60.0, 90))
