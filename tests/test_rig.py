"""FaceRig: evaluation against hand sums, actors, masks and the errors users see."""
import numpy as np
import pytest

from facedyn.performance import Topology
from facedyn.rig import FaceRig, ShapeOffsets, rigid_falloff


def strip(length: int = 20, spacing: float = 0.25) -> tuple[np.ndarray, Topology]:
    """A flat strip of quads along x, two vertices high: distances along it are exact."""
    x = np.arange(length + 1) * spacing
    points = np.concatenate([np.stack([x, 0 * x, 0 * x], 1), np.stack([x, 0 * x + spacing, 0 * x], 1)])
    i = np.arange(length)
    quads = np.stack([i, i + 1, i + length + 2, i + length + 1], 1)
    return points.astype(np.float32), Topology(np.full(length, 4, np.int32), quads.ravel().astype(np.int32))


@pytest.fixture
def rig() -> FaceRig:
    points, topology = strip()
    n = len(points)
    rng = np.random.default_rng(0)
    return FaceRig(
        name="strip",
        neutral=points,
        topology=topology,
        expression_names=("jawOpen", "mouthSmile_L", "eyeBlink_L"),
        expression_offsets=(
            ([0, 5, 9], rng.normal(size=(3, 3))),
            ([1, 2], rng.normal(size=(2, 3))),
            ([n - 1], rng.normal(size=(1, 3))),
        ),
        identity_modes=rng.normal(size=(2, n, 3)),
        rigid_vertices=[0, n // 2],
        landmarks={"nose_base": 3},
    )


def hand_sum(rig: FaceRig, weights: np.ndarray) -> np.ndarray:
    out = rig.neutral.astype(np.float64).copy()
    for w, (indices, offsets) in zip(weights, rig.expression_offsets):
        out[indices] += w * offsets
    return out


def test_evaluate_matches_a_hand_sum_for_one_frame_and_many(rig):
    weights = np.array([0.7, -0.2, 1.0])
    np.testing.assert_allclose(rig.evaluate(weights), hand_sum(rig, weights), atol=1e-5)
    frames = np.random.default_rng(1).uniform(size=(5, 3))
    posed = rig.evaluate(frames)
    assert posed.shape == (5, rig.point_count, 3) and posed.dtype == np.float32
    for frame, w in zip(posed, frames):
        np.testing.assert_allclose(frame, hand_sum(rig, w), atol=1e-5)
    np.testing.assert_array_equal(rig.evaluate(np.zeros(3)), rig.neutral)


def test_dense_and_sparse_bases_agree():
    """Shapes that fill the basis take the dense (BLAS) path, sparse ones the CSR path."""
    points, topology = strip()
    n = len(points)
    rng = np.random.default_rng(2)
    dense = rng.normal(size=(4, n, 3)).astype(np.float32)
    sparse = dense * (rng.uniform(size=(4, n, 1)) < 0.05)
    weights = rng.uniform(size=(3, 4))
    for offsets in (dense, sparse):
        rig = FaceRig("r", points, topology, expression_names=tuple("abcd"), expression_offsets=offsets)
        expected = points + np.einsum("fk,knc->fnc", weights, offsets)
        np.testing.assert_allclose(rig.evaluate(weights), expected, atol=1e-5)


def test_dense_offsets_are_stored_sparse(rig):
    points, topology = strip()
    dense = np.zeros((1, len(points), 3), np.float32)
    dense[0, [4, 7]] = [[1, 2, 3], [4, 5, 6]]
    stored = FaceRig("r", points, topology, expression_names=("a",), expression_offsets=dense)
    (shape,) = stored.expression_offsets
    assert isinstance(shape, ShapeOffsets)
    np.testing.assert_array_equal(shape.indices, [4, 7])
    np.testing.assert_array_equal(stored.dense_offsets("a"), dense[0])


def test_weights_from_named_curves(rig):
    np.testing.assert_array_equal(rig.weights_from({"eyeBlink_L": 0.5}), [0.0, 0.0, 0.5])
    curves = rig.weights_from({"jawOpen": [0.0, 0.5, 1.0], "eyeBlink_L": 0.25})
    np.testing.assert_array_equal(curves, [[0.0, 0.0, 0.25], [0.5, 0.0, 0.25], [1.0, 0.0, 0.25]])
    with pytest.raises(ValueError, match="one length"):
        rig.weights_from({"jawOpen": [0.0, 1.0], "eyeBlink_L": [1.0, 2.0, 3.0]})


def test_shape_index_and_unknown_names(rig):
    assert rig.shape_index("mouthSmile_L") == 1
    with pytest.raises(ValueError, match=r"no expression 'jawopen'.*did you mean jawOpen"):
        rig.shape_index("jawopen")
    with pytest.raises(ValueError, match="no expression 'tongueOut'"):
        rig.weights_from({"tongueOut": 1.0})


@pytest.mark.parametrize("weights", [np.zeros(2), np.zeros((4, 5)), np.zeros((2, 2, 3))])
def test_weights_of_the_wrong_shape_are_refused(rig, weights):
    with pytest.raises(ValueError, match=r"K = 3 expressions"):
        rig.evaluate(weights)


def test_a_rig_without_blend_shapes_says_so():
    points, topology = strip()
    bare = FaceRig("bare", points, topology)
    with pytest.raises(ValueError, match="'bare' has no expression shapes"):
        bare.evaluate([])
    with pytest.raises(ValueError, match="'bare' has no identity modes"):
        bare.make_actor(seed=0)


def test_make_actor_adds_identity_modes_and_keeps_expressions(rig):
    c = np.array([0.5, -1.5])
    actor = rig.make_actor(c, scale=2.0)
    np.testing.assert_allclose(actor.neutral, rig.neutral + 2.0 * np.tensordot(c, rig.identity_modes, 1), atol=1e-5)
    weights = np.array([1.0, 0.5, -0.5])
    np.testing.assert_allclose(actor.evaluate(weights) - actor.neutral, rig.evaluate(weights) - rig.neutral, atol=1e-5)
    assert actor.metadata["identity_coefficients"] == [1.0, -3.0]
    assert actor.landmarks == rig.landmarks and actor.name == "strip_actor"
    np.testing.assert_array_equal(actor.rigid_weights, rig.rigid_weights)


def test_make_actor_from_a_seed_is_reproducible(rig):
    a, b, other = rig.make_actor(seed=3), rig.make_actor(seed=3), rig.make_actor(seed=4)
    np.testing.assert_array_equal(a.neutral, b.neutral)
    assert not np.allclose(a.neutral, other.neutral)
    assert a.name == "strip_actor3"
    np.testing.assert_allclose(rig.make_actor(seed=3, scale=0.0).neutral, rig.neutral)


def test_make_actor_refuses_bad_arguments(rig):
    with pytest.raises(ValueError, match="exactly one"):
        rig.make_actor()
    with pytest.raises(ValueError, match="exactly one"):
        rig.make_actor([1.0, 2.0], seed=1)
    with pytest.raises(ValueError, match="expected 2 identity coefficients"):
        rig.make_actor([1.0, 2.0, 3.0])


def test_rigid_falloff_follows_the_skin():
    points, topology = strip(length=40, spacing=0.1)
    rigid = np.flatnonzero(points[:, 0] == 0.0)
    weights = rigid_falloff(points, topology, rigid, falloff=1.5)
    np.testing.assert_array_equal(weights[rigid], 1.0)
    bottom = weights[:41]
    t = np.clip(points[:41, 0] / 1.5, 0, 1)
    np.testing.assert_allclose(bottom, 1 - t * t * (3 - 2 * t), atol=1e-5)
    assert np.all(np.diff(bottom) <= 0) and bottom[-1] == 0.0
    assert weights.dtype == np.float32


def test_rig_masks_default_and_validate(rig):
    points, topology = strip()
    plain = FaceRig("plain", points, topology)
    np.testing.assert_array_equal(plain.face_vertices, np.arange(len(points)))
    assert plain.rigid_vertices.size == 0 and not plain.rigid_weights.any()
    assert rig.rigid_weights[0] == 1.0 and rig.rigid_weights[rig.point_count // 2] == 1.0
    with pytest.raises(ValueError, match="landmark vertices out of range"):
        FaceRig("bad", points, topology, landmarks={"nose_base": 10_000})
    with pytest.raises(ValueError, match="face_vertices must be vertex indices"):
        FaceRig("bad", points, topology, face_vertices=[-1])
    with pytest.raises(ValueError, match="rigid weights must be"):
        FaceRig("bad", points, topology, rigid_weights=np.full(len(points), 2.0))
    with pytest.raises(ValueError, match=r"neutral must be \(N, 3\)"):
        FaceRig("bad", points[:, :2], topology)
    with pytest.raises(ValueError, match="2 expression names for 1 offset sets"):
        FaceRig("bad", points, topology, expression_names=("a", "b"), expression_offsets=(([0], [[1, 0, 0]]),))
    with pytest.raises(ValueError, match="lists a vertex more than once"):
        FaceRig("bad", points, topology, expression_names=("a",), expression_offsets=(([1, 1], np.ones((2, 3))),))
    with pytest.raises(ValueError, match="moves vertices outside"):
        FaceRig("bad", points, topology, expression_names=("a",), expression_offsets=(([999], [[1, 0, 0]]),))
