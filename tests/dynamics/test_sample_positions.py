"""F reading each skin sample's rest position beside its velocities (TrainConfig.sample_positions)."""
import numpy as np
import pytest
from synthetic_face import curved_sheet, jiggle, platform_motion, top_rows
from test_removal_arrays import one_torch_thread  # noqa: F401 (an autouse fixture: one torch thread)

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.modelfile import load_model, save_model
from facedyn.dynamics.removal import SAMPLE_POSITIONS, remove_dynamics, sample_positions, skin_inputs
from facedyn.dynamics.skull_motion import SkullMotionInput
from facedyn.dynamics.training import TrainConfig, train_removal
from facedyn.dynamics.training_sequence import TrainingSequence

ROWS, COLS, FPS = 12, 10, 120.0
NOISE_CM = 0.02  # tracking noise: its velocity (about 3 cm/s) swamps the slow offsets' (about 0.6 cm/s)


@pytest.fixture(scope="module")
def noisy_slow_takes():
    """Slow platforms (1.5-2.5 Hz, below the 5 Hz tissue): each vertex's offset is its own gain
    (0 at the rigid top, growing downwards) times one spring's response, under tracking
    noise, so a sample's velocities barely say how strongly it moves; its position does."""
    pts, topo = curved_sheet(ROWS, COLS)
    pts[:, 1] *= 0.5
    face = FaceSetup.build(topo, pts, rigid_vertices=top_rows(ROWS, COLS, 2), sample_count=24)
    y = pts[:, 1]
    gain = np.clip((y.max() - y) / (y.max() - y.min()), 0, 1) ** 1.5
    gain[face.rigid_vertices] = 0.0
    rng = np.random.default_rng(0)
    takes = []
    for i, hz in enumerate((1.5, 2.0, 2.5, 1.75)):
        t, q = platform_motion(360, FPS, hz, seed=20 + i)
        offsets = (gain[None, :, None] * jiggle(t, q, FPS)[:, None, :]).astype(np.float32)
        captured = (pts[None] + offsets + rng.normal(0, NOISE_CM, offsets.shape)).astype(np.float32)
        takes.append(TrainingSequence(f"slow_{i}", captured, FPS, t, q, "skull", offsets))
    return face, takes


def removal_error(face, takes, positions: bool) -> tuple[float, object]:
    held = takes[-1]
    config = TrainConfig(epochs=20, batch_size=1000, validation=(held.name,), seed=0, target="truth",
                         skull_motion=SkullMotionInput(), sample_positions=positions)
    model = train_removal(takes, face, config)
    _, removed = remove_dynamics(held.points, held.translate, held.orient, FPS, model, "numpy")
    inner = slice(20, -20)
    error = np.sqrt(np.mean((removed[inner] - held.dynamics[inner]) ** 2)) / np.sqrt(np.mean(held.dynamics[inner] ** 2))
    return float(error), model


@pytest.mark.slow  # trains F for 20 epochs, with and without positions
def test_positions_tell_f_which_sample_it_removes_from(noisy_slow_takes, tmp_path):
    face, takes = noisy_slow_takes
    without, plain = removal_error(face, takes, positions=False)
    with_positions, model = removal_error(face, takes, positions=True)
    assert SAMPLE_POSITIONS not in plain.arrays and plain.network.spec.inputs == 5 * 41 * 3 + 63
    assert model.network.spec.inputs == 5 * 41 * 3 + 63 + 3
    np.testing.assert_array_equal(model.arrays[SAMPLE_POSITIONS], face.rest_points[face.samples].astype(np.float32))
    assert with_positions < 0.7 * without, (with_positions, without)
    # the model file keeps the input, so a loaded F removes the same offsets
    loaded = load_model(save_model(model, tmp_path / "f.removal"))
    held = takes[-1]
    _, before = remove_dynamics(held.points, held.translate, held.orient, FPS, model, "numpy")
    _, after = remove_dynamics(held.points, held.translate, held.orient, FPS, loaded, "numpy", chunk_frames=50)
    np.testing.assert_allclose(after, before, atol=1e-6)
    # a model whose position input does not fit its samples is refused, not misread
    loaded.arrays[SAMPLE_POSITIONS] = loaded.arrays[SAMPLE_POSITIONS][:-1]
    with pytest.raises(ValueError, match="one 3-vector per skin sample"):
        remove_dynamics(held.points, held.translate, held.orient, FPS, loaded, "numpy")


def test_skin_inputs_append_the_positions_to_every_frame():
    skin = np.arange(2 * 3 * 4, dtype=np.float32).reshape(2, 3, 4)
    positions = np.arange(9, dtype=np.float32).reshape(3, 3)
    joined = skin_inputs(skin, positions)
    assert joined.shape == (2, 3, 7)
    np.testing.assert_array_equal(joined[:, :, :4], skin)
    np.testing.assert_array_equal(joined[1, :, 4:], positions)
    assert skin_inputs(skin, None) is skin


def test_sample_positions_are_the_samples_rest_points(noisy_slow_takes):
    face, _ = noisy_slow_takes
    np.testing.assert_array_equal(sample_positions(face), face.rest_points[face.samples].astype(np.float32))
