import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from facedyn.geometry import dualquat


def random_dq(rng, n):
    rot = Rotation.random(n, random_state=rng)
    t = rng.normal(size=(n, 3)) * 5
    q = rot.as_quat()[:, [3, 0, 1, 2]]  # scipy is scalar-last
    return dualquat.from_translate_orient(t, q), rot, t


def test_translate_orient_round_trip_and_matrix_match_scipy():
    rng = np.random.default_rng(0)
    dq, rot, t = random_dq(rng, 20)
    m = dualquat.to_matrix(dq)
    np.testing.assert_allclose(m[:, :3, :3], rot.as_matrix(), atol=1e-12)
    np.testing.assert_allclose(m[:, :3, 3], t, atol=1e-12)
    np.testing.assert_allclose(m[:, 3], np.tile([0, 0, 0, 1.0], (20, 1)))
    t2, q2 = dualquat.to_translate_orient(dq)
    np.testing.assert_allclose(t2, t, atol=1e-12)
    np.testing.assert_allclose(Rotation.from_quat(q2[:, [1, 2, 3, 0]]).as_matrix(), rot.as_matrix(), atol=1e-12)
    back = dualquat.from_matrix(m)
    np.testing.assert_allclose(dualquat.to_matrix(back), m, atol=1e-12)


def test_product_is_composition_and_conjugate_is_inverse():
    rng = np.random.default_rng(1)
    a, _, _ = random_dq(rng, 10)
    b, _, _ = random_dq(rng, 10)
    np.testing.assert_allclose(
        dualquat.to_matrix(dualquat.multiply(a, b)), dualquat.to_matrix(a) @ dualquat.to_matrix(b), atol=1e-10
    )
    ident = dualquat.multiply(a, dualquat.conjugate(a))
    np.testing.assert_allclose(ident, dualquat.identity((10,)), atol=1e-12)


def test_transform_points_matches_scipy_batched():
    rng = np.random.default_rng(2)
    dq, rot, t = random_dq(rng, 4)
    p = rng.normal(size=(4, 7, 3))
    expected = np.stack([rot[i].apply(p[i]) + t[i] for i in range(4)])
    np.testing.assert_allclose(dualquat.transform_points(dq, p), expected, atol=1e-10)


def test_normalize_gives_unit_rigid_dual_quaternion():
    rng = np.random.default_rng(3)
    raw = rng.normal(size=(50, 8))
    n = dualquat.normalize(raw)
    np.testing.assert_allclose(np.linalg.norm(n[:, :4], axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(np.sum(n[:, :4] * n[:, 4:], axis=1), 0.0, atol=1e-12)
    dq, _, _ = random_dq(rng, 5)
    np.testing.assert_allclose(dualquat.normalize(3.7 * dq), dq, atol=1e-12)
    np.testing.assert_allclose(dualquat.normalize(dq), dq, atol=1e-12)  # idempotent on unit input


def _fd(f, x, eps=1e-6):
    g = np.zeros_like(x)
    for i in np.ndindex(x.shape):
        e = np.zeros_like(x)
        e[i] = eps
        g[i] = (f(x + e) - f(x - e)) / (2 * eps)
    return g


def test_normalize_vjp_matches_finite_differences():
    rng = np.random.default_rng(4)
    raw = rng.normal(size=(3, 8))
    grad = rng.normal(size=(3, 8))
    analytic = dualquat.normalize_vjp(raw, grad)
    numeric = _fd(lambda x: np.sum(dualquat.normalize(x) * grad), raw)
    np.testing.assert_allclose(analytic, numeric, atol=1e-7)


def test_rotation_translation_vjp_through_normalize_matches_finite_differences():
    rng = np.random.default_rng(5)
    raw = rng.normal(size=(4, 8))
    g_rot = rng.normal(size=(4, 3, 3))
    g_t = rng.normal(size=(4, 3))

    def f(x):
        rot, t = dualquat.to_rotation_translation(dualquat.normalize(x))
        return np.sum(rot * g_rot) + np.sum(t * g_t)

    unit = dualquat.normalize(raw)
    analytic = dualquat.normalize_vjp(raw, dualquat.rotation_translation_vjp(unit, g_rot, g_t))
    np.testing.assert_allclose(analytic, _fd(f, raw), atol=1e-7)


def test_make_continuous_flips_to_one_hemisphere():
    rng = np.random.default_rng(6)
    dq, _, _ = random_dq(rng, 1)
    seq = np.repeat(dq, 6, axis=0) * np.array([1, -1, 1, -1, -1, 1.0])[:, None]
    out = dualquat.make_continuous(seq)
    assert np.all(np.sum(out[1:, :4] * out[:-1, :4], axis=1) > 0)


def test_bad_shapes_raise():
    with pytest.raises(ValueError, match="last axis of 8"):
        dualquat.normalize(np.zeros((2, 7)))
    with pytest.raises(ValueError, match="zero real part"):
        dualquat.normalize(np.zeros(8))
    with pytest.raises(ValueError, match=r"\(..., N, 3\)"):
        dualquat.transform_points(dualquat.identity(), np.zeros(3))
    with pytest.raises(ValueError, match="4, 4"):
        dualquat.from_matrix(np.eye(3))
