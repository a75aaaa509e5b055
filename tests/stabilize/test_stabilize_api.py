import numpy as np
import pytest
import torch

from facedyn.geometry import quaternion, rigid
from facedyn.kernels import runtime
from facedyn.stabilize import Schedule, stabilize
from facedyn.stabilize.synthetic import synthetic_take


@pytest.fixture(scope="module")
def take():
    return synthetic_take(frames=180, vertices=400, fps=120.0, seed=3)


def median_error(result, take):
    return float(np.median(np.linalg.norm(result.skull_points - take.skull, axis=-1)))


def test_mode_pursuit_recovers_the_skull_motion_better_than_three_point(take):
    mp = stabilize(take.world, take.fps, rest=take.rest)
    tp = stabilize(take.world, take.fps, method="three-point", rest=take.rest, three_point=take.three_point)
    assert take.deforming.mean() > 0.3  # a good part of the face moves non-rigidly
    assert median_error(mp, take) <= 0.01
    assert median_error(mp, take) < 0.5 * median_error(tp, take)
    # facedyn's convention: world = R(orient) skull + translate
    world = np.einsum("fij,fnj->fni", quaternion.to_matrix(mp.orient), mp.skull_points) + mp.translate[:, None]
    np.testing.assert_allclose(world, take.world, atol=1e-3)
    assert np.degrees(quaternion.angle_between(mp.orient, take.orient)).max() < 0.1
    assert len(mp.history) == 5 and mp.energy == pytest.approx(mp.history[-1].energy, rel=1e-2)
    assert mp.solve_error.shape == (180,) and mp.solve_error.dtype == np.float32
    assert {"init", "solve", "total"} <= set(mp.timings)


def test_rest_estimated_from_the_data(take):
    result = stabilize(take.world, take.fps)
    assert result.rest.shape == (400, 3)
    # the skull space is the estimate's own (near frame 0's); compare up to that one transform
    rot, trans = rigid.kabsch(result.skull_points.reshape(-1, 3), take.skull.reshape(-1, 3))
    aligned = rigid.apply(rot, trans, result.skull_points.astype(np.float64))
    assert np.median(np.linalg.norm(aligned - take.skull, axis=-1)) <= 0.01


@pytest.fixture
def one_torch_thread():
    """PyTorch's intra-op threads spin-wait against other processes on a busy machine
    (a 0.3 s solve took 40 s); the reference needs none for a test this small."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.mark.slow  # runs the reference solver / a long take
def test_fast_and_reference_reach_the_same_energy(one_torch_thread):
    """Same energy, same schedule: the two L-BFGS runs take different paths through a
    non-convex landscape, so single takes land within a few 0.1% of each other either
    way; over several takes the fast solver must be as good on average and as accurate."""
    schedule = Schedule(iterations=8)
    gaps = []
    for seed in (4, 5, 6):
        small = synthetic_take(frames=90, vertices=150, fps=120.0, seed=seed)
        fast = stabilize(small.world, small.fps, rest=small.rest, schedule=schedule, solver="fast")
        ref = stabilize(small.world, small.fps, rest=small.rest, schedule=schedule, solver="reference")
        assert fast.energy == pytest.approx(ref.energy, rel=1e-2)
        assert abs(median_error(fast, small) - median_error(ref, small)) < 2e-3
        gaps.append(fast.energy / ref.energy - 1.0)
    assert np.mean(gaps) < 5e-3


@pytest.mark.slow  # runs the reference solver / a long take
def test_long_takes_in_chunks_match_one_solve():
    long = synthetic_take(frames=420, vertices=200, fps=120.0, seed=5)
    whole = stabilize(long.world, long.fps, rest=long.rest)
    parts = stabilize(long.world, long.fps, rest=long.rest, chunk_frames=160, chunk_overlap=32)
    assert median_error(parts, long) <= 0.01
    diff = np.linalg.norm(parts.skull_points - whole.skull_points, axis=-1)
    assert np.median(diff) < 0.005
    estimated = stabilize(long.world, long.fps, chunk_frames=160, chunk_overlap=32)
    rot, trans = rigid.kabsch(estimated.skull_points.reshape(-1, 3), long.skull.reshape(-1, 3))
    aligned = rigid.apply(rot, trans, estimated.skull_points.astype(np.float64))
    assert np.median(np.linalg.norm(aligned - long.skull, axis=-1)) <= 0.01


@pytest.mark.skipif(not runtime.available(), reason=f"no OpenCL device: {runtime.unavailable_reason()}")
def test_numpy_and_opencl_backends_agree(take):
    a = stabilize(take.world, take.fps, rest=take.rest, backend="numpy")
    b = stabilize(take.world, take.fps, rest=take.rest, backend="opencl")
    assert a.energy == pytest.approx(b.energy, rel=5e-4)  # float32 paths differ in the last digits
    assert np.median(np.linalg.norm(a.skull_points - b.skull_points, axis=-1)) < 1e-3


def test_weights_mask_and_initializations(take):
    rigid_only = (~take.deforming).astype(float)
    masked = stabilize(take.world, take.fps, rest=take.rest, weights=rigid_only, init="procrustes")
    assert median_error(masked, take) <= 0.01
    assert masked.skull_points.shape == take.world.shape
    three = stabilize(take.world, take.fps, rest=take.rest, init="three-point", three_point=take.three_point)
    assert median_error(three, take) <= 0.01


def test_baselines(take):
    errors = {
        m: median_error(stabilize(take.world, take.fps, method=m, rest=take.rest, three_point=take.three_point), take)
        for m in ("three-point", "procrustes", "icp")
    }
    assert errors["icp"] < errors["procrustes"]
    no_rest = stabilize(take.world, take.fps, method="procrustes")
    np.testing.assert_allclose(no_rest.rest, take.world[0], atol=1e-6)  # reference frame's pose
    np.testing.assert_allclose(no_rest.translate[0], 0.0, atol=1e-9)


def test_bad_inputs_raise(take):
    with pytest.raises(ValueError, match=r"\(frames, N, 3\)"):
        stabilize(take.world[0], 120.0)
    with pytest.raises(ValueError, match="rest must be"):
        stabilize(take.world, 120.0, rest=take.rest[:10])
    with pytest.raises(ValueError, match="weights must be"):
        stabilize(take.world, 120.0, weights=np.ones(3))
    with pytest.raises(ValueError, match="method"):
        stabilize(take.world, 120.0, method="magic")
    with pytest.raises(ValueError, match="fps"):
        stabilize(take.world, -1.0)
    with pytest.raises(ValueError, match="three_point"):
        stabilize(take.world, 120.0, method="three-point")
    bad = take.world.copy()
    bad[3, 4, 1] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        stabilize(bad, 120.0)


def test_a_still_capture_solves_as_a_still_skull(take):
    """Every frame repeats the first: nothing moved (not a tracker holding one fit), so the skull stays put."""
    still = np.repeat(take.world[:1], 40, axis=0)
    result = stabilize(still, take.fps)
    assert result.tracked.all()
    np.testing.assert_allclose(result.translate - result.translate[0], 0.0, atol=1e-5)  # cm: the solver's tolerance
    assert np.degrees(quaternion.angle_between(result.orient, result.orient[:1])).max() < 1e-4
    np.testing.assert_allclose(result.skull_points, result.skull_points[:1].repeat(40, axis=0), atol=1e-5)
