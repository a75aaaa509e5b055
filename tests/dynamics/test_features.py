"""Skull and skin features against a direct transcription of papers/000 eqs. (1)-(4)."""
import numpy as np
import pytest
from opencl_marks import BACKENDS, requires_opencl

from facedyn.dynamics.features import compute_features
from facedyn.dynamics.skull import to_world
from facedyn.geometry import quaternion


def homogeneous(translate, orient):
    """(F, 4, 4) skull transforms T(t) as the paper writes them."""
    m = np.zeros((len(translate), 4, 4))
    m[:, :3, :3] = quaternion.to_matrix(orient)
    m[:, :3, 3] = translate
    m[:, 3, 3] = 1.0
    return m


def paper_features(world, translate, orient, landmarks, fps, w):
    """Eqs. (1)-(4) literally, with loops, 4x4 matrices and indices clamped to [0, F-1]."""
    T = homogeneous(translate, orient)
    f, s = world.shape[:2]
    dt = 1.0 / fps
    clamp = lambda k: min(max(k, 0), f - 1)  # noqa: E731
    B = np.zeros((f, len(landmarks), 2 * w + 1, 3))
    X = np.zeros((f, s, 2 * w + 1, 3))
    for t in range(f):
        for j, k in enumerate(range(t - w, t + w + 1)):
            a, b = clamp(k - 1), clamp(k)
            rel = np.eye(4) - np.linalg.inv(T[b]) @ T[a]
            for l, bl in enumerate(landmarks):
                B[t, l, j] = (rel @ np.append(bl, 1.0))[:3] / dt
            for i in range(s):
                xk = np.linalg.inv(T[b]) @ np.append(world[b, i], 1.0)
                xk1 = np.linalg.inv(T[a]) @ np.append(world[a, i], 1.0)
                X[t, i, j] = (xk - xk1)[:3] / dt
    return B.reshape(f, -1), X.reshape(f, s, -1)


def rotating_take(frames=18, samples=4, seed=1):
    rng = np.random.default_rng(seed)
    translate = np.cumsum(rng.normal(0, 0.3, (frames, 3)), axis=0) + [0.0, 150.0, 0.0]
    orient = quaternion.from_rotvec(np.cumsum(rng.normal(0, 0.04, (frames, 3)), axis=0))
    skull = rng.normal(0, 6, (1, samples, 3)) + np.cumsum(rng.normal(0, 0.05, (frames, samples, 3)), axis=0)
    world = to_world(skull, translate, orient).astype(np.float32)
    landmarks = rng.normal(0, 6, (5, 3))
    return world, translate, orient, landmarks


def scale_of(a):
    return np.abs(a).max()


@pytest.mark.parametrize("backend", BACKENDS)
def test_matches_paper_transcription_with_rotating_skull(backend):
    world, t, q, lms = rotating_take()
    B_ref, X_ref = paper_features(world.astype(np.float64), t, q, lms, 96.0, w=3)
    feats = compute_features(world, t, q, lms, 96.0, space="world", window=3, backend=backend)
    assert feats.skull.shape == (18, 5 * 7 * 3) and feats.skin.shape == (18, 4, 21)
    np.testing.assert_allclose(feats.skull, B_ref, atol=1e-5 * scale_of(B_ref))
    np.testing.assert_allclose(feats.skin, X_ref, atol=1e-5 * scale_of(X_ref))


def test_default_window_sizes_match_paper():
    world, t, q, lms = rotating_take(frames=25)
    feats = compute_features(world, t, q, lms, 120.0, space="world", backend="numpy")
    assert feats.skull.shape == (25, 315) and feats.skin.shape == (25, 4, 63)
    B_ref, X_ref = paper_features(world.astype(np.float64), t, q, lms, 120.0, w=10)
    np.testing.assert_allclose(feats.skull, B_ref, atol=1e-6 * scale_of(B_ref))
    np.testing.assert_allclose(feats.skin, X_ref, atol=1e-6 * scale_of(X_ref))


@pytest.mark.parametrize("backend", BACKENDS)
def test_constant_velocity_known_answers(backend):
    f, fps, w = 30, 120.0, 10
    v_world = np.array([3.0, -6.0, 1.5])  # cm/s, the skull translating steadily
    r0 = quaternion.from_axis_angle([0.3, 1.0, 0.2], 0.7)  # a fixed, non-trivial head pose
    t = np.arange(f)[:, None] / fps * v_world + [1.0, 2.0, -2.0]
    q = np.repeat(r0[None], f, axis=0)
    u_skull = np.array([0.5, 0.25, -1.0])  # cm/s, the skin sliding steadily over the skull
    skull = np.array([[1.0, 2.0, 3.0], [-2.0, 0.0, 5.0]])[None] + np.arange(f)[:, None, None] / fps * u_skull
    world = to_world(skull, t, q).astype(np.float64)
    lms = np.array([[0.0, 5.0, 6.0], [5.0, 2.0, 1.0], [-5.0, 2.0, 1.0], [0.0, 2.0, -6.0], [0.0, -3.0, 6.0]])
    feats = compute_features(world, t, q, lms, fps, space="world", window=w, backend=backend)
    B = feats.skull.reshape(f, 5, 2 * w + 1, 3)
    X = feats.skin.reshape(f, 2, 2 * w + 1, 3)
    expected_b = quaternion.to_matrix(r0).T @ v_world  # world velocity in the skull frame
    tol = 1e-4
    # Window entry j of frame t is the pair (k-1, k), k = t - w + j; zero where k <= 0 or k >= F.
    for t_ in (0, 5, 15, 29):
        k = t_ - w + np.arange(2 * w + 1)
        inside = (k >= 1) & (k <= f - 1)
        np.testing.assert_allclose(B[t_][:, inside], np.broadcast_to(expected_b, B[t_][:, inside].shape), atol=tol)
        np.testing.assert_allclose(X[t_][:, inside], np.broadcast_to(u_skull, X[t_][:, inside].shape), atol=tol)
        assert np.all(B[t_][:, ~inside] == 0) and np.all(X[t_][:, ~inside] == 0)


def test_constant_spin_known_answer():
    """A skull spinning about Y at omega: bdot = (I - Ry(-omega dt)) b / dt for every pair."""
    f, fps, omega = 15, 100.0, 2.0
    q = quaternion.from_axis_angle([0.0, 1.0, 0.0], omega * np.arange(f) / fps)
    t = np.zeros((f, 3))
    b = np.array([[4.0, 1.0, 2.0], [0.0, 3.0, -5.0], [1.0, -1.0, 1.0]])
    feats = compute_features(np.zeros((f, 1, 3)), t, q, b, fps, window=2, backend="numpy")
    step = quaternion.to_matrix(quaternion.from_axis_angle([0.0, 1.0, 0.0], -omega / fps))
    expected = (b - b @ step.T) * fps  # (L, 3)
    B = feats.skull.reshape(f, 3, 5, 3)
    np.testing.assert_allclose(B[7], np.repeat(expected[:, None], 5, axis=1), rtol=1e-6)
    # Skin fixed in skull space has zero skin velocity however the skull spins.
    assert np.all(feats.skin == 0)


def test_skull_and_world_inputs_agree_and_fps_scales():
    world, t, q, lms = rotating_take()
    from facedyn.dynamics.skull import to_skull

    skull = to_skull(world.astype(np.float64), t, q)
    a = compute_features(world.astype(np.float64), t, q, lms, 120.0, space="world", backend="numpy")
    b = compute_features(skull, t, q, lms, 120.0, space="skull", backend="numpy")
    np.testing.assert_allclose(a.skin, b.skin, atol=1e-6 * scale_of(a.skin))
    np.testing.assert_array_equal(a.skull, b.skull)
    c = compute_features(skull, t, q, lms, 60.0, space="skull", backend="numpy")
    np.testing.assert_allclose(c.skin, b.skin / 2, rtol=1e-6)


@pytest.mark.parametrize("backend", BACKENDS)
def test_frame_ranges_match_the_whole_take(backend):
    world, t, q, lms = rotating_take(frames=40)
    whole = compute_features(world, t, q, lms, 120.0, space="world", backend=backend)
    for a, b in ((0, 7), (7, 23), (23, 40), (12, 13)):
        part = compute_features(world, t, q, lms, 120.0, space="world", frame_range=(a, b), backend=backend)
        np.testing.assert_allclose(part.skull, whole.skull[a:b], atol=1e-6 * scale_of(whole.skull))
        np.testing.assert_allclose(part.skin, whole.skin[a:b], atol=1e-6 * scale_of(whole.skin))


@requires_opencl
def test_opencl_matches_numpy_on_a_realistic_take():
    """float32 kernel vs float64 reference, world points 150 cm from the origin."""
    world, t, q, lms = rotating_take(frames=200, samples=344, seed=3)
    ref = compute_features(world, t, q, lms, 120.0, space="world", backend="numpy")
    out = compute_features(world, t, q, lms, 120.0, space="world", backend="opencl")
    np.testing.assert_allclose(out.skull, ref.skull, rtol=0, atol=1e-5 * scale_of(ref.skull))
    np.testing.assert_allclose(out.skin, ref.skin, rtol=0, atol=1e-5 * scale_of(ref.skin))


def test_bad_input_is_a_clear_error():
    world, t, q, lms = rotating_take()
    with pytest.raises(ValueError, match="fps"):
        compute_features(world, t, q, lms, 0.0)
    with pytest.raises(ValueError, match="backend"):
        compute_features(world, t, q, lms, 120.0, backend="cuda")
    with pytest.raises(ValueError, match="frames, points, 3"):
        compute_features(world[0], t, q, lms, 120.0)
    with pytest.raises(ValueError, match="translate"):
        compute_features(world, t[:-1], q, lms, 120.0)
    with pytest.raises(ValueError, match="landmarks"):
        compute_features(world, t, q, lms[:, :2], 120.0)
    with pytest.raises(ValueError, match="frame_range"):
        compute_features(world, t, q, lms, 120.0, frame_range=(5, 5))
