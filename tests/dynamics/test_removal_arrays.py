"""Training network F on synthetic takes with a known dynamics law, then removal."""
import numpy as np
import pytest
import torch
from synthetic_face import curved_sheet, jiggle, platform_motion, top_rows

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.modelfile import DynamicsModel, ModelMismatch, load_model, save_model
from facedyn.dynamics.network import Network, removal_spec
from facedyn.dynamics.removal import remove_dynamics
from facedyn.dynamics.skull import to_world
from facedyn.dynamics.skull_motion import SkullMotionInput
from facedyn.dynamics.training import TrainConfig, train_removal
from facedyn.dynamics.training_sequence import TrainingSequence

ROWS, COLS, FPS = 12, 10, 120.0


@pytest.fixture(scope="module", autouse=True)
def one_torch_thread():
    """Small batches on a shared 2-core machine: one thread avoids OpenMP oversubscription."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def gains(points):
    """How strongly each vertex jiggles: 0 at the rigid top, growing smoothly downwards."""
    y = points[:, 1]
    return np.clip((y.max() - y) / (y.max() - y.min()), 0, 1) ** 1.5


@pytest.fixture(scope="module")
def corpus():
    pts, topo = curved_sheet(ROWS, COLS)
    pts[:, 1] *= 0.5  # a 10 cm tall face
    face = FaceSetup.build(topo, pts, rigid_vertices=top_rows(ROWS, COLS, 2), sample_count=24)
    g = gains(pts)
    g[face.rigid_vertices] = 0.0
    takes, truth = [], {}
    # The held-out take vibrates at 120 / 21 Hz, between the training rates: one period fits
    # the 21-frame average exactly, so its moving-average targets equal the true offsets
    # and removal can be judged against the truth.
    for i, hz in enumerate((5.0, 6.5, 8.0, FPS / 21.0)):
        t, q = platform_motion(240, FPS, hz, seed=i)
        offsets = g[None, :, None] * jiggle(t, q, FPS)[:, None, :]
        name = f"platform_{i}"
        takes.append({"name": name, "points": to_world(pts[None] + offsets, t, q).astype(np.float32), "fps": FPS, "translate": t, "orient": q, "space": "world"})
        truth[name] = offsets
    return face, takes, truth


@pytest.fixture(scope="module")
def trained(corpus):
    face, takes, _ = corpus
    config = TrainConfig(epochs=30, batch_size=1000, validation=("platform_3",), seed=0)
    curve = []
    model = train_removal(takes, face, config, progress=lambda e, tr, va: curve.append((e, tr, va)))
    return model, curve


@pytest.mark.slow  # trains F for 30 epochs
def test_training_reaches_a_low_validation_error(trained):
    model, curve = trained
    val = model.info["validation"]
    assert len(curve) == 30 and curve[-1][1] < curve[0][1]
    assert val["rms_cm"] < 0.15 * val["zero_offset_rms_cm"], val
    assert model.info["training"]["takes"][-1] == {"name": "platform_3", "frames": 240, "space": "world", "validation": True}


def test_training_is_seeded(corpus):
    face, takes, _ = corpus
    config = TrainConfig(epochs=2, batch_size=2000, subsample=0.5, seed=3)
    a = train_removal(takes[:2], face, config)
    b = train_removal(takes[:2], face, config)
    assert a.info["loss_curve"] == b.info["loss_curve"]


@pytest.mark.slow  # trains F for 30 epochs
def test_removal_recovers_the_held_expression(trained, corpus, tmp_path):
    face, takes, truth = corpus
    model = load_model(save_model(trained[0], tmp_path / "f.fdyn"), topology=face.topology, fps=FPS)
    take = takes[-1]  # held out of training
    quasistatic, offsets = remove_dynamics(take["points"], take["translate"], take["orient"], FPS, model, space="world")
    inner = slice(20, -20)
    true = truth[take["name"]][inner]
    err = np.sqrt(np.mean((offsets[inner] - true) ** 2))
    assert err < 0.15 * np.sqrt(np.mean(true**2))
    rest = face.rest_points[None].astype(np.float32)
    assert np.sqrt(np.mean((quasistatic[inner] - rest) ** 2)) < 0.15 * np.sqrt(np.mean(true**2))
    assert np.all(offsets[:, face.rigid_vertices] == 0)


@pytest.fixture(scope="module")
def random_model(corpus):
    face, _, _ = corpus
    torch.manual_seed(1)
    return DynamicsModel("removal", Network(removal_spec()), face, FPS, {"skull": 10, "skin": 10, "target": 10})


def test_world_and_skull_inputs_and_chunks_agree(random_model, corpus):
    _, takes, _ = corpus
    take = takes[0]
    from facedyn.dynamics.skull import to_skull

    skull = to_skull(take["points"], take["translate"], take["orient"]).astype(np.float32)
    q1, o1 = remove_dynamics(take["points"], take["translate"], take["orient"], FPS, random_model, "numpy", space="world")
    q2, o2 = remove_dynamics(skull, take["translate"], take["orient"], FPS, random_model, "numpy", chunk_frames=17)
    np.testing.assert_allclose(o1, o2, atol=1e-4 * np.abs(o1).max())
    np.testing.assert_allclose(q2, skull - o2)
    np.testing.assert_allclose(q1, q2, atol=1e-4)


def test_acceleration_input_trains_and_removes_in_chunks(corpus):
    """F with facedyn's skull input (accelerations over t-30..t+10): the model records it,
    and chunked removal slices the whole take's skull features exactly."""
    face, takes, _ = corpus
    config = TrainConfig(epochs=2, batch_size=1000, validation=("platform_3",), skull_motion=SkullMotionInput())
    model = train_removal(takes, face, config)
    assert model.skull_motion == SkullMotionInput() and model.network.spec.inputs == 5 * 41 * 3 + 63
    take = takes[0]
    _, whole = remove_dynamics(take["points"], take["translate"], take["orient"], FPS, model, "numpy", space="world", chunk_frames=1000)
    _, chunked = remove_dynamics(take["points"], take["translate"], take["orient"], FPS, model, "numpy", space="world", chunk_frames=17)
    np.testing.assert_allclose(chunked, whole, atol=1e-6)


def test_removal_network_equals_the_plain_forward(random_model):
    net = random_model.network
    rng = np.random.default_rng(0)
    net.set_normalization(rng.normal(size=378), rng.uniform(0.5, 2, 378), rng.normal(size=3), 0.2)
    b, x = torch.randn(4, 315), torch.randn(4, 6, 63)
    with torch.no_grad():
        split = net.forward_split(b, x)
        plain = net(torch.cat([b[:, None].expand(4, 6, 315), x], dim=2))
    torch.testing.assert_close(split, plain, rtol=1e-5, atol=1e-5)


def test_bad_input_is_a_clear_error(random_model, corpus):
    face, takes, _ = corpus
    take = takes[0]
    with pytest.raises(ModelMismatch, match="96 fps"):
        remove_dynamics(take["points"], take["translate"], take["orient"], 96.0, random_model)
    with pytest.raises(ValueError, match="points per frame"):
        remove_dynamics(take["points"][:, :-1], take["translate"], take["orient"], FPS, random_model)
    with pytest.raises(ValueError, match="different frame rates"):
        train_removal([takes[0], dict(takes[1], fps=96.0)], face, TrainConfig(epochs=1))
    with pytest.raises(ValueError, match="unknown take keys"):
        train_removal([dict(takes[0], colour="red")], face)
    with pytest.raises(ValueError, match="too few"):
        train_removal([TrainingSequence("short", take["points"][:15], FPS, take["translate"][:15], take["orient"][:15], "world")], face)


@pytest.mark.slow  # trains F twice, 10 epochs each
def test_true_targets_recover_slow_dynamics_the_moving_average_cannot_see(corpus):
    """Platforms at 1.5-2.5 Hz drive the 5 Hz tissue below resonance: its offsets change
    slowly, so the 21-frame moving average keeps most of them and its targets miss them;
    F trained on the true dynamics (a simulated corpus's) removes them."""
    face, _, _ = corpus
    pts = face.rest_points
    g = gains(pts)
    g[face.rigid_vertices] = 0.0
    takes = []
    for i, hz in enumerate((1.5, 2.0, 2.5, 1.75)):
        t, q = platform_motion(360, FPS, hz, seed=10 + i)
        offsets = (g[None, :, None] * jiggle(t, q, FPS)[:, None, :]).astype(np.float32)
        takes.append(TrainingSequence(f"slow_{i}", (pts[None] + offsets).astype(np.float32), FPS, t, q, "skull", offsets))
    held = takes[-1]
    errors = {}
    for target in ("moving-average", "truth"):
        # 10 epochs leave 0.86 / 0.13 of the held take's dynamics (30 epochs: 0.86 / 0.09): far from either bound
        config = TrainConfig(epochs=10, batch_size=1000, validation=(held.name,), seed=0, target=target)
        model = train_removal(takes, face, config)
        _, removed = remove_dynamics(held.points, held.translate, held.orient, FPS, model, "numpy")
        inner = slice(20, -20)
        errors[target] = np.sqrt(np.mean((removed[inner] - held.dynamics[inner]) ** 2)) / np.sqrt(np.mean(held.dynamics[inner] ** 2))
    assert errors["moving-average"] > 0.5, errors  # the paper's targets see little of slow dynamics
    assert errors["truth"] < 0.5 * errors["moving-average"], errors


def test_true_targets_need_known_dynamics(corpus):
    face, takes, _ = corpus
    with pytest.raises(ValueError, match="target must be one of"):
        TrainConfig(target="median")
    with pytest.raises(ValueError, match="has no known dynamics"):
        train_removal(takes[:2], face, TrainConfig(epochs=1, target="truth"))
    wrong = dict(takes[0], dynamics=np.zeros((3, face.point_count, 3), np.float32))
    with pytest.raises(ValueError, match="dynamics are"):
        train_removal([wrong, takes[1]], face, TrainConfig(epochs=1, target="truth"))
