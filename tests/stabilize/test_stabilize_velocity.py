import numpy as np
import pytest

from facedyn.stabilize.velocity import derivative_operator, stencil_weights


def test_interior_stencil_is_the_seven_point_central_difference():
    np.testing.assert_allclose(stencil_weights(np.arange(-3, 4)) * 60, [-1, 9, -45, 0, 45, -9, 1], atol=1e-10)


@pytest.mark.parametrize("frames", [7, 8, 30])
def test_exact_on_degree_six_polynomials_including_the_ends(frames):
    fps = 96.0
    t = np.arange(frames) / fps
    d = derivative_operator(frames, fps)
    for k in range(7):
        np.testing.assert_allclose(d @ t**k, k * t ** max(k - 1, 0) if k else 0 * t, atol=1e-6 * (1 + k))
    assert d.shape == (frames, frames)
    assert d.nnz <= 7 * frames


def test_sixth_order_convergence():
    errors = []
    for fps in (60.0, 120.0):
        t = np.arange(40) / fps
        errors.append(np.abs(derivative_operator(40, fps) @ np.sin(5 * t) - 5 * np.cos(5 * t))[3:-3].max())
    assert errors[0] / errors[1] > 2**5.5


def test_short_takes_use_every_frame():
    d = derivative_operator(3, 10.0)
    t = np.arange(3) / 10.0
    np.testing.assert_allclose(d @ (t**2), 2 * t, atol=1e-9)
    assert derivative_operator(1, 10.0).nnz == 0
    with pytest.raises(ValueError, match="fps"):
        derivative_operator(5, 0.0)
