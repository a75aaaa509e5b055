import numpy as np
import pytest

from facedyn.stabilize.penalty import fade, fade_terms


def test_fade_shape_matches_the_paper():
    np.testing.assert_allclose(fade([0.0, 0.25, 0.5, 0.75, 1.0, 3.0]), [0.0, 0.125, 0.5, 0.875, 1.0, 1.0])
    u = np.linspace(0, 1.5, 3001)
    v = fade(u)
    assert np.all(np.diff(v) >= 0)  # monotone, saturating
    slope = np.gradient(v, u)
    assert np.abs(np.diff(slope)).max() < 1e-2  # C1: no jump in the derivative
    np.testing.assert_allclose(fade(-u), v)


@pytest.mark.parametrize("weighted", [False, True])
def test_fade_terms_energy_and_gradient(weighted):
    rng = np.random.default_rng(0)
    x = rng.normal(size=(5, 3, 40)) * 0.6
    w = rng.random(40) if weighted else None
    width = 0.8
    ref_weights = np.ones(40) if w is None else w

    def energy(a):
        return float(np.sum(fade(np.abs(a) / width) * ref_weights))

    out, scratch, tmp = np.empty_like(x), np.empty_like(x), np.empty_like(x)
    e = fade_terms(x, width, out, scratch, w, tmp)
    np.testing.assert_allclose(e, energy(x), rtol=1e-12)
    grad = 4.0 / width**2 * ref_weights * out
    eps = 1e-6
    for idx in [(0, 0, 0), (1, 2, 5), (4, 1, 39), (2, 0, 17)]:
        d = np.zeros_like(x)
        d[idx] = eps
        np.testing.assert_allclose(grad[idx], (energy(x + d) - energy(x - d)) / (2 * eps), atol=1e-6)
    # scratch may be x itself
    y = x.copy()
    assert fade_terms(y, width, out, y, w, tmp) == pytest.approx(e, rel=1e-12)


def test_fade_terms_float32_sums_stay_accurate():
    rng = np.random.default_rng(1)
    x = (rng.normal(size=(400, 3, 1000)) * 0.5).astype(np.float32)
    out, scratch = np.empty_like(x), np.empty_like(x)
    e = fade_terms(x, 0.8, out, scratch)
    assert e == pytest.approx(float(np.sum(fade(np.abs(x.astype(np.float64)) / 0.8))), rel=2e-6)


def test_bad_width_raises():
    x = np.zeros((1, 3, 2))
    with pytest.raises(ValueError, match="positive"):
        fade_terms(x, 0.0, x.copy(), x.copy())
    with pytest.raises(ValueError, match="tmp"):
        fade_terms(x, 1.0, x.copy(), x.copy(), np.ones(2))
