import numpy as np
import pytest
from scipy.interpolate import BSpline

from facedyn.geometry import bspline


def random_clamped_knots(rng, inner=6):
    t = np.sort(rng.uniform(0.0, 10.0, inner))
    return np.concatenate([[0.0] * 4, t, [10.0] * 4])


def test_basis_matches_scipy_design_matrix_and_is_a_partition_of_unity():
    rng = np.random.default_rng(0)
    knots = random_clamped_knots(rng)
    x = np.concatenate([rng.uniform(0, 10, 200), [0.0, 10.0], knots[4:-4]])
    b = bspline.basis(knots, x)
    expected = BSpline.design_matrix(x, knots, 3).toarray()
    np.testing.assert_allclose(b.toarray(), expected, atol=1e-12)
    np.testing.assert_allclose(np.asarray(b.sum(axis=1)).ravel(), 1.0, atol=1e-12)
    assert b.toarray().min() >= 0.0
    assert np.all(np.diff(b.indptr) == 4)  # local support: 4 non-zeros per row
    assert b.shape == (len(x), bspline.control_count(knots))


@pytest.mark.parametrize("degree", [1, 2, 3])
def test_basis_other_degrees_match_scipy(degree):
    knots = bspline.clamped_uniform_knots(5, 0.0, 1.0, degree)
    x = np.linspace(0, 1, 37)
    np.testing.assert_allclose(
        bspline.basis(knots, x, degree).toarray(), BSpline.design_matrix(x, knots, degree).toarray(), atol=1e-12
    )


def test_derivative_matches_scipy_and_finite_differences():
    rng = np.random.default_rng(1)
    knots = random_clamped_knots(rng)
    controls = rng.normal(size=(bspline.control_count(knots), 2))
    x = rng.uniform(0.1, 9.9, 50)
    d = bspline.basis(knots, x, derivative=1) @ controls
    np.testing.assert_allclose(d, BSpline(knots, controls, 3).derivative()(x), atol=1e-10)
    h = 1e-6
    fd = (bspline.evaluate(knots, controls, x + h) - bspline.evaluate(knots, controls, x - h)) / (2 * h)
    np.testing.assert_allclose(d, fd, atol=1e-6)
    np.testing.assert_allclose(np.asarray(bspline.basis(knots, x, derivative=1).sum(axis=1)).ravel(), 0.0, atol=1e-10)


def test_midpoint_refinement_leaves_the_curve_unchanged():
    rng = np.random.default_rng(2)
    knots = bspline.clamped_uniform_knots(4, 0.0, 50.0)
    controls = rng.normal(size=(bspline.control_count(knots), 8))
    new_knots, new_controls = bspline.refine_midpoints(knots, controls)
    assert len(new_controls) == len(controls) + 4
    np.testing.assert_allclose(new_knots, bspline.clamped_uniform_knots(8, 0.0, 50.0))
    x = np.linspace(0, 50, 301)
    refined = bspline.evaluate(new_knots, new_controls, x)
    np.testing.assert_allclose(refined, bspline.evaluate(knots, controls, x), atol=1e-12)
    np.testing.assert_allclose(BSpline(new_knots, new_controls, 3)(x), BSpline(knots, controls, 3)(x), atol=1e-12)
    # non-uniform knots too
    knots = random_clamped_knots(rng)
    controls = rng.normal(size=(bspline.control_count(knots), 3))
    k2, c2 = bspline.refine_midpoints(knots, controls)
    x = np.linspace(0, 10, 301)
    np.testing.assert_allclose(bspline.evaluate(k2, c2, x), bspline.evaluate(knots, controls, x), atol=1e-12)


def test_insert_knot_keeps_the_curve():
    knots = bspline.clamped_uniform_knots(3)
    controls = np.arange(12.0).reshape(6, 2) ** 2
    k2, c2 = bspline.insert_knot(knots, controls, 0.4)
    assert len(k2) == len(knots) + 1 and len(c2) == 7
    x = np.linspace(0, 1, 55)
    np.testing.assert_allclose(bspline.evaluate(k2, c2, x), bspline.evaluate(knots, controls, x), atol=1e-12)


def test_bad_inputs_raise():
    knots = bspline.clamped_uniform_knots(3)
    with pytest.raises(ValueError, match="domain"):
        bspline.basis(knots, [1.5])
    with pytest.raises(ValueError, match="non-decreasing"):
        bspline.basis(knots[::-1], [0.5])
    with pytest.raises(ValueError, match="controls"):
        bspline.insert_knot(knots, np.zeros((3, 2)), 0.5)
    with pytest.raises(ValueError, match="at least one span"):
        bspline.clamped_uniform_knots(0)
