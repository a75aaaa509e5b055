import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from facedyn.geometry import rigid


def rigid_pair(rng, frames=6, n=50):
    source = rng.normal(size=(frames, n, 3)) * 5
    rot = Rotation.random(frames, random_state=rng)
    t = rng.normal(size=(frames, 3)) * 10
    target = np.stack([rot[i].apply(source[i]) for i in range(frames)]) + t[:, None]
    return source, target, rot.as_matrix(), t


def test_kabsch_recovers_batched_transforms():
    rng = np.random.default_rng(0)
    s, x, r, t = rigid_pair(rng)
    rot, trans = rigid.kabsch(s, x)
    np.testing.assert_allclose(rot, r, atol=1e-10)
    np.testing.assert_allclose(trans, t, atol=1e-9)
    # extra batch axes
    rot2, _ = rigid.kabsch(s.reshape(2, 3, 50, 3), x.reshape(2, 3, 50, 3))
    np.testing.assert_allclose(rot2.reshape(6, 3, 3), r, atol=1e-10)


def test_weighted_kabsch_matches_scipy_align_vectors():
    rng = np.random.default_rng(1)
    s = rng.normal(size=(40, 3))
    x = Rotation.random(random_state=rng).apply(s) + rng.normal(size=(40, 3)) * 0.3 + [1, 2, 3]
    w = rng.random(40)
    rot, trans = rigid.kabsch(s, x, w)
    cs = (w[:, None] * s).sum(0) / w.sum()
    cx = (w[:, None] * x).sum(0) / w.sum()
    expected, _ = Rotation.align_vectors(x - cx, s - cs, weights=w)
    np.testing.assert_allclose(rot, expected.as_matrix(), atol=1e-9)
    np.testing.assert_allclose(trans, cx - rot @ cs, atol=1e-9)


def test_kabsch_never_returns_a_reflection():
    rng = np.random.default_rng(2)
    s = rng.normal(size=(30, 3))
    rot, _ = rigid.kabsch(s, s * np.array([1.0, 1.0, -1.0]))  # best orthogonal fit is a mirror
    np.testing.assert_allclose(np.linalg.det(rot), 1.0)
    np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)


@pytest.mark.parametrize("loss", ["geman-mcclure", "huber", "trim"])
def test_robust_icp_ignores_deforming_points(loss):
    rng = np.random.default_rng(3)
    s, x, r, t = rigid_pair(rng, frames=4, n=200)
    x = x.copy()
    x[:, :60] += rng.normal(size=(4, 60, 3)) * 2.0  # 30 % of the points deform
    plain, _ = rigid.kabsch(s, x)
    rot, trans, weights = rigid.robust_icp(s, x, loss=loss, iterations=15)
    assert np.abs(plain - r).max() > 1e-2
    np.testing.assert_allclose(rot, r, atol=1e-5)
    np.testing.assert_allclose(trans, t, atol=1e-4)
    assert weights[:, 60:].mean() > 5 * weights[:, :60].mean()


def test_robust_icp_respects_prior_mask_and_fixed_scale():
    rng = np.random.default_rng(4)
    s, x, r, _ = rigid_pair(rng, frames=2, n=100)
    x = x.copy()
    x[:, :50] += 3.0
    mask = np.r_[np.zeros(50), np.ones(50)]
    rot, _, _ = rigid.robust_icp(s, x, mask, scale=0.1, iterations=3)
    np.testing.assert_allclose(rot, r, atol=1e-8)


def test_three_point_is_exact_on_rigid_triples():
    rng = np.random.default_rng(5)
    s, x, r, t = rigid_pair(rng)
    x = x.copy()
    x[:, 10:] += rng.normal(size=x[:, 10:].shape)  # only the chosen vertices stay rigid
    rot, trans = rigid.three_point(s, x, (0, 4, 7))
    np.testing.assert_allclose(rot, r, atol=1e-10)
    np.testing.assert_allclose(trans, t, atol=1e-9)
    frame, origin = rigid.three_point_frame(s[:, [0, 4, 7]])
    np.testing.assert_allclose(frame @ np.swapaxes(frame, 1, 2), np.broadcast_to(np.eye(3), (6, 3, 3)), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(frame), 1.0)
    np.testing.assert_allclose(origin, s[:, [0, 4, 7]].mean(1))


def test_bad_inputs_raise():
    p = np.zeros((5, 3))
    with pytest.raises(ValueError, match="5 points, target 4"):
        rigid.kabsch(p, np.zeros((4, 3)))
    with pytest.raises(ValueError, match="non-negative"):
        rigid.kabsch(p, p, -np.ones(5))
    with pytest.raises(ValueError, match="collinear"):
        rigid.three_point(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]]), np.eye(3), (0, 1, 2))
    with pytest.raises(ValueError, match="3 distinct"):
        rigid.three_point(p, p, (0, 0, 1))
    with pytest.raises(ValueError, match="loss"):
        rigid.robust_icp(p, p, loss="l0")
