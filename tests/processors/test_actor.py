"""Actors: one skull frame per actor, from a rig, a neutral, or (with the rigidity estimate) takes."""
import numpy as np
import pytest

from facedyn.cli import main
from facedyn.sim.corpus import TakeSpec, simulate_take
from facedyn.sim.default_face import default_face
from facedyn.usd.actor_asset import read_actor
from facedyn.usd.blendshape_rig import write_blendshape_rig
from facedyn.usd.take import read_take

from usd_fixtures import write_mesh_cache


def cli(*argv):
    return main([str(a) for a in argv] + ["-q"])


@pytest.fixture(scope="module")
def rig_and_takes(tmp_path_factory):
    """The built-in face as a UsdSkel rig, and a held smile under a walk and under a hop as plain caches
    (metres, Z up, first frame 1001: nothing but points)."""
    folder = tmp_path_factory.mktemp("actor")
    rig = default_face(12)
    rig_path = write_blendshape_rig(rig, folder / "rig.usda")
    caches = {}
    for motion, seed in (("walk", 1), ("hop", 2)):
        take = simulate_take(rig, TakeSpec(f"smile_{motion}", motion, "smile", duration_s=1.0, seed=seed, noise_cm=0.002))
        world = take.world_points().astype(np.float64)
        z_up_metres = np.stack([world[..., 0], -world[..., 2], world[..., 1]], axis=-1) / 100.0
        counts, indices = rig.topology.face_vertex_counts, rig.topology.face_vertex_indices
        caches[motion] = (write_mesh_cache(folder / f"{motion}.usda", z_up_metres, counts, indices, up_axis="Z", meters_per_unit=1.0), take)
    return folder, rig, rig_path, caches


def test_actor_from_a_rig_keeps_the_rigs_space(rig_and_takes, tmp_path):
    _, rig, rig_path, _ = rig_and_takes
    assert cli("actor", rig_path, "-o", tmp_path / "actor.usda") == 0
    actor = read_actor(tmp_path / "actor.usda")
    np.testing.assert_allclose(actor.neutral, rig.neutral, atol=1e-5)
    np.testing.assert_allclose(actor.rigid_weights, rig.rigid_weights, atol=1e-6)
    assert actor.source == "rig" and actor.skin_samples is not None and len(actor.landmarks) >= 3
    assert actor.topology.fingerprint() == rig.topology.fingerprint()
    assert cli("actor", rig_path, "-o", tmp_path / "actor.txt") == 2


def test_two_takes_of_one_held_expression_share_the_actors_skull_frame(rig_and_takes, tmp_path):
    folder, rig, rig_path, caches = rig_and_takes
    assert cli("actor", rig_path, "-o", tmp_path / "actor.usda") == 0
    shapes = {}
    for motion, (cache, take) in caches.items():
        shot = tmp_path / motion
        shot.mkdir()
        assert cli("import", cache, "-o", shot / "capture.usdc") == 0
        assert cli("stabilize", shot / "take.usda", "-o", shot / "stabilized.usdc", "--attach", shot / "take.usda",
                   "--actor", tmp_path / "actor.usda") == 0
        perf, _ = read_take(shot / "take.usda")
        # The skin in skull space is the actor's (the rig's) space: compare with the truth directly.
        truth_skull = take.quasistatic + take.offsets
        error = np.linalg.norm(perf.points - truth_skull, axis=-1)[:, rig.face_vertices]
        assert np.median(error) < 0.01, np.median(error)
        shapes[motion] = perf.points
    # The same held expression under two motions lands in one skull frame: the parts that follow the skull sit at
    # the same skull-space place in both takes, to within the tracking noise (the soft parts differ by the
    # motion's own jiggle and the sag of a tilted head, which the simulator counts as quasistatic).
    rigid = np.flatnonzero(rig.rigid_weights >= 0.99)
    mean_difference = np.linalg.norm(shapes["walk"].mean(0) - shapes["hop"].mean(0), axis=-1)[rigid]
    assert np.median(mean_difference) < 0.002, np.median(mean_difference)


def test_models_refuse_takes_in_another_skull_frame(rig_and_takes, tmp_path, capsys):
    from facedyn.processors.model_steps import check_skull_frame
    from facedyn.processors.training_inputs import take_skull_frame
    from facedyn.usd.errors import TakeError

    _, rig, rig_path, caches = rig_and_takes
    cache, _ = caches["walk"]
    assert cli("import", cache, "-o", tmp_path / "capture.usdc") == 0
    assert cli("stabilize", tmp_path / "take.usda", "-o", tmp_path / "stabilized.usdc", "--attach", tmp_path / "take.usda",
               "--rest", "estimate") == 0
    plain, _ = read_take(tmp_path / "take.usda")

    class Model:
        info = {"skull_frame": take_skull_frame(plain.with_changes(rest_points=rig.neutral))}

    with pytest.raises(TakeError, match="another skull frame.*--actor"):
        check_skull_frame(tmp_path / "take.usda", plain, "f.removal", Model())
    with pytest.raises(TakeError, match="plain take stabilized without --actor"):
        check_skull_frame(tmp_path / "take.usda", plain.with_changes(rest_points=None), "f.removal", Model())
    check_skull_frame(tmp_path / "take.usda", plain.with_changes(rest_points=rig.neutral), "f.removal", Model())
    assert cli("stabilize", tmp_path / "take.usda", "-o", tmp_path / "s2.usdc", "--actor", tmp_path / "none.usda") == 1


def test_actor_from_takes_finds_the_rigid_region_and_one_frame(rig_and_takes, tmp_path):
    _, rig, _, caches = rig_and_takes
    assert cli("actor", caches["walk"][0], caches["hop"][0], "--from", "takes", "-o", tmp_path / "actor.usda") == 0
    actor = read_actor(tmp_path / "actor.usda")
    assert actor.source == "takes" and actor.rigid_weights is not None
    found_rigid = actor.rigid_weights >= 0.99
    truly_rigid = rig.rigid_weights >= 0.99
    # most of what it calls rigid is rigid, and it finds a good share of the truly rigid vertices
    assert np.mean(truly_rigid[found_rigid]) > 0.8 and np.mean(found_rigid[truly_rigid]) > 0.3


def import_with_actor(cache, shot, actor):
    shot.mkdir()
    assert cli("import", cache, "-o", shot / "capture.usdc", "--actor", actor) == 0
    return shot / "take.usda"


@pytest.mark.slow  # imports, stabilizes and trains on the actor's takes
def test_import_records_the_actor_and_stabilize_and_the_trainers_use_it(rig_and_takes, tmp_path):
    from facedyn.dynamics.modelfile import load_model
    from facedyn.performance import skull_frame_id
    from facedyn.usd.rootedit import recorded_actor
    from facedyn.usd.stackstatus import open_root

    _, rig, rig_path, caches = rig_and_takes
    assert cli("actor", rig_path, "-o", tmp_path / "actors" / "ada.usda") == 0
    actor = read_actor(tmp_path / "actors" / "ada.usda")
    roots = []
    for motion, (cache, take) in caches.items():
        root = import_with_actor(cache, tmp_path / motion, tmp_path / "actors" / "ada.usda")
        assert dict(open_root(root).customLayerData)["facedyn"]["actor"] == "../actors/ada.usda"  # relative: moves with the shots
        assert recorded_actor(root) == (tmp_path / "actors" / "ada.usda").resolve()
        assert cli("stabilize", root, "-o", root.parent / "stabilized.usdc", "--attach", root) == 0  # no --actor: the recorded one
        perf, _ = read_take(root)
        assert skull_frame_id(perf.rest_points, perf.topology) == actor.skull_frame
        np.testing.assert_array_equal(perf.skin_samples, actor.skin_samples)
        error = np.linalg.norm(perf.points - (take.quasistatic + take.offsets), axis=-1)[:, rig.face_vertices]
        assert np.median(error) < 0.01, np.median(error)
        roots.append(root)
    # The model takes the actor's samples and landmarks whichever take comes first, and records the actor and its frame.
    # (the second with a budget its reading of the takes already spent: one of its 3 epochs)
    for order, model_path, flags in ((roots, tmp_path / "a.removal", ("--epochs", "1")),
                                     (roots[::-1], tmp_path / "b.removal", ("--epochs", "3", "--budget-minutes", "1e-6"))):
        assert cli("train-removal", *order, "-o", model_path, *flags, "--validation", "walk") == 0
    a, b = load_model(tmp_path / "a.removal"), load_model(tmp_path / "b.removal")
    assert len(b.info["loss_curve"]) == 1 and b.info["training"]["config"]["time_limit_s"] == pytest.approx(6e-5)
    assert a.info["actor"] == "ada" and a.info["skull_frame"] == actor.skull_frame
    np.testing.assert_array_equal(a.face.samples, actor.skin_samples)
    np.testing.assert_array_equal(b.face.samples, a.face.samples)
    np.testing.assert_allclose(a.face.landmarks, actor.landmarks, atol=1e-6)


def test_actor_errors_name_the_files(rig_and_takes, tmp_path, capsys):
    _, rig, rig_path, caches = rig_and_takes
    other = write_blendshape_rig(default_face(6), tmp_path / "other_rig.usda")
    assert cli("actor", other, "-o", tmp_path / "other.usda") == 0
    tmp_path.joinpath("shot").mkdir()
    # an actor of another mesh is refused at import, and nothing is written
    assert cli("import", caches["walk"][0], "-o", tmp_path / "shot" / "capture.usdc", "--actor", tmp_path / "other.usda") == 1
    assert not (tmp_path / "shot" / "take.usda").exists()
    assert cli("actor", rig_path, "-o", tmp_path / "ada.usda") == 0
    root = import_with_actor(caches["walk"][0], tmp_path / "walk", tmp_path / "ada.usda")
    assert cli("stabilize", root, "-o", tmp_path / "walk" / "s.usdc", "--attach", root, "--mask", "all") == 0
    assert cli("stabilize", root, "-o", tmp_path / "walk" / "s.usdc", "--attach", root, "--rest", "estimate") == 2
    # the trainers refuse an actor whose skull frame the takes are not in (here: the walk's own first frame)
    assert cli("actor", caches["walk"][0], "--from", "neutral", "-o", tmp_path / "first_frame.usda") == 0
    capsys.readouterr()
    assert cli("train-removal", root, "-o", tmp_path / "f.removal", "--epochs", "1", "--actor", tmp_path / "first_frame.usda") == 1
    assert "the training takes are not in the actor first_frame's skull frame" in capsys.readouterr().err
    (tmp_path / "ada.usda").rename(tmp_path / "moved.usda")
    assert cli("stabilize", root, "-o", tmp_path / "walk" / "s.usdc") == 1  # the recorded actor is gone
    assert "records the actor ../ada.usda, which does not exist" in capsys.readouterr().err
