import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from facedyn.geometry import bspline, dualquat, sdlb


def random_controls(rng, n, spread=0.3):
    rotvec = np.cumsum(rng.normal(size=(n, 3)) * spread, axis=0)
    q = Rotation.from_rotvec(rotvec).as_quat()[:, [3, 0, 1, 2]]
    return dualquat.from_translate_orient(rng.normal(size=(n, 3)) * 3, q)


def setup(rng, n_spans=5, frames=40):
    knots = bspline.clamped_uniform_knots(n_spans, 0.0, frames - 1)
    basis = bspline.basis(knots, np.arange(frames, dtype=float))
    return basis, random_controls(rng, bspline.control_count(knots))


def test_blend_is_rigid_and_interpolates_equal_controls():
    rng = np.random.default_rng(0)
    basis, controls = setup(rng)
    dq = sdlb.blend(basis, controls)
    p = rng.normal(size=(dq.shape[0], 20, 3))
    moved = dualquat.transform_points(dq, p)
    dist = lambda a: np.linalg.norm(a[:, :, None] - a[:, None], axis=-1)  # noqa: E731
    np.testing.assert_allclose(dist(moved), dist(p), atol=1e-10)
    rot, _ = dualquat.to_rotation_translation(dq)
    np.testing.assert_allclose(np.linalg.det(rot), 1.0, atol=1e-12)
    same = np.repeat(controls[:1], len(controls), axis=0)
    np.testing.assert_allclose(sdlb.blend(basis, same), np.repeat(controls[:1], dq.shape[0], axis=0), atol=1e-12)


def test_blend_is_blind_to_control_signs():
    rng = np.random.default_rng(1)
    basis, controls = setup(rng)
    flipped = controls * np.where(rng.random(len(controls)) < 0.5, -1.0, 1.0)[:, None]
    a = sdlb.blend(basis, controls)
    b = sdlb.blend(basis, flipped)
    np.testing.assert_allclose(dualquat.to_matrix(a), dualquat.to_matrix(b), atol=1e-12)


def _fd(f, x, eps=1e-6):
    g = np.zeros_like(x)
    for i in np.ndindex(x.shape):
        e = np.zeros_like(x)
        e[i] = eps
        g[i] = (f(x + e) - f(x - e)) / (2 * eps)
    return g


def test_blend_vjp_matches_finite_differences():
    rng = np.random.default_rng(2)
    basis, controls = setup(rng, n_spans=3, frames=15)
    controls[2] *= -1.0  # exercise the sign alignment
    grad = rng.normal(size=(15, 8))
    analytic = sdlb.blend_vjp(basis, controls, grad)
    numeric = _fd(lambda c: np.sum(sdlb.blend(basis, c) * grad), controls)
    np.testing.assert_allclose(analytic, numeric, atol=1e-7)


def test_points_gradient_through_sdlb_matches_finite_differences():
    rng = np.random.default_rng(3)
    basis, controls = setup(rng, n_spans=2, frames=9)
    points = rng.normal(size=(9, 6, 3))
    weights = rng.normal(size=(9, 6, 3))

    def energy(c):
        return np.sum(weights * dualquat.transform_points(sdlb.blend(basis, c), points))

    dq = sdlb.blend(basis, controls)
    analytic = sdlb.blend_vjp(basis, controls, sdlb.transform_points_vjp(dq, points, weights))
    np.testing.assert_allclose(analytic, _fd(energy, controls), atol=1e-6)


def test_fit_controls_reproduces_a_spline_motion():
    rng = np.random.default_rng(4)
    basis, controls = setup(rng, n_spans=4, frames=60)
    signs = np.where(rng.random(60) < 0.3, -1.0, 1.0)[:, None]
    fitted = sdlb.fit_controls(basis, sdlb.blend_raw(basis, controls) * signs)
    np.testing.assert_allclose(
        dualquat.to_matrix(sdlb.blend(basis, fitted)), dualquat.to_matrix(sdlb.blend(basis, controls)), atol=1e-5
    )
    # per-frame unit dual quaternions (not exactly a spline after normalization): close
    fitted = sdlb.fit_controls(basis, sdlb.blend(basis, controls) * signs)
    np.testing.assert_allclose(
        dualquat.to_matrix(sdlb.blend(basis, fitted)), dualquat.to_matrix(sdlb.blend(basis, controls)), atol=0.05
    )


def test_bad_shapes_raise():
    rng = np.random.default_rng(5)
    basis, controls = setup(rng)
    with pytest.raises(ValueError, match=r"\(n, 8\)"):
        sdlb.blend(basis, controls[:, :4])
    with pytest.raises(ValueError, match="does not match"):
        sdlb.blend(basis, controls[:-1])
