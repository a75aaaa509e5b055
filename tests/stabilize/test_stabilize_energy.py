import numpy as np
import pytest
import torch

from facedyn.geometry import bspline, dualquat, quaternion
from facedyn.kernels import runtime
from facedyn.stabilize.energy import NumpyEnergy
from facedyn.stabilize.objective import ControlObjective
from facedyn.stabilize.penalty import fade
from facedyn.stabilize.reference import TorchModel
from facedyn.stabilize.velocity import derivative_operator

FPS = 30.0


def problem(rng, frames=14, n=12, dtype=np.float64, weighted=False):
    points = rng.normal(size=(frames, 3, n))
    rest = points[0] + rng.normal(size=(3, n)) * 0.3
    weights = rng.random(n) if weighted else None
    return points.astype(dtype), rest.astype(dtype), derivative_operator(frames, FPS), weights


def transforms(rng, frames, spread=0.05):
    rot = quaternion.to_matrix(quaternion.from_rotvec(rng.normal(size=(frames, 3)) * spread))
    return rot, rng.normal(size=(frames, 3)) * spread


def brute_energy(points, rest, rot, trans, wp, wv, weights=None):
    s = np.einsum("fij,fjn->fin", rot, points) + trans[:, :, None]
    v = (derivative_operator(len(points), FPS) @ s.reshape(len(points), -1)).reshape(s.shape)
    w = 1.0 if weights is None else weights
    return float(np.sum(w * fade(np.abs(s - rest) / wp)) + np.sum(w * fade(np.abs(v) / wv)))


@pytest.mark.parametrize("weighted", [False, True])
def test_numpy_energy_value_and_gradient_match_brute_force_and_finite_differences(weighted):
    rng = np.random.default_rng(0)
    points, rest, vel, weights = problem(rng, weighted=weighted)
    rot, trans = transforms(rng, len(points))
    energy = NumpyEnergy(points, rest, vel, weights, dtype=np.float64)
    wp, wv = 0.5, 4.0
    e_pos, e_vel, g_rot, g_trans = energy(rot, trans, wp, wv)
    assert e_pos + e_vel == pytest.approx(brute_energy(points, rest, rot, trans, wp, wv, weights), rel=1e-12)
    eps = 1e-6
    for f, i, j in [(0, 0, 0), (3, 1, 2), (13, 2, 1), (7, 0, 2)]:
        d = np.zeros_like(rot)
        d[f, i, j] = eps
        plus = brute_energy(points, rest, rot + d, trans, wp, wv, weights)
        minus = brute_energy(points, rest, rot - d, trans, wp, wv, weights)
        assert g_rot[f, i, j] == pytest.approx((plus - minus) / (2 * eps), abs=1e-5)
    for f, i in [(0, 0), (6, 1), (13, 2)]:
        d = np.zeros_like(trans)
        d[f, i] = eps
        plus = brute_energy(points, rest, rot, trans + d, wp, wv, weights)
        minus = brute_energy(points, rest, rot, trans - d, wp, wv, weights)
        assert g_trans[f, i] == pytest.approx((plus - minus) / (2 * eps), abs=1e-5)


def spline_controls(rng, frames, spans=3):
    knots = bspline.clamped_uniform_knots(spans, 0.0, frames - 1)
    n = bspline.control_count(knots)
    q = quaternion.from_rotvec(rng.normal(size=(n, 3)) * 0.05)
    controls = dualquat.from_translate_orient(rng.normal(size=(n, 3)) * 0.05, q)
    controls[1] *= -1.0  # antipodal control: the objective must align it
    return bspline.basis(knots, np.arange(frames, dtype=float)), controls


def test_control_objective_gradient_matches_finite_differences():
    rng = np.random.default_rng(1)
    points, rest, vel, weights = problem(rng, weighted=True)
    basis, controls = spline_controls(rng, len(points))
    objective = ControlObjective(basis, NumpyEnergy(points, rest, vel, weights, dtype=np.float64), 0.5, 4.0)
    x = controls.ravel()
    value, grad = objective(x)
    assert value == pytest.approx(objective.value(x))
    eps = 1e-6
    for i in range(0, len(x), 3):
        d = np.zeros_like(x)
        d[i] = eps
        assert grad[i] == pytest.approx((objective.value(x + d) - objective.value(x - d)) / (2 * eps), abs=2e-5)


@pytest.mark.skipif(not runtime.available(), reason=f"no OpenCL device: {runtime.unavailable_reason()}")
@pytest.mark.parametrize("weighted", [False, True])
@pytest.mark.parametrize("frames", [1, 5, 40])
def test_opencl_matches_numpy(weighted, frames):
    from facedyn.stabilize.opencl import OpenCLEnergy

    rng = np.random.default_rng(2)
    points, rest, vel, weights = problem(rng, frames=frames, n=203, dtype=np.float32, weighted=weighted)
    rot, trans = transforms(rng, frames)
    ref = NumpyEnergy(points, rest, vel, weights, dtype=np.float64)(rot, trans, 0.8, 6.0)
    got = OpenCLEnergy(points, rest, vel, weights)(rot, trans, 0.8, 6.0)
    np_ = NumpyEnergy(points, rest, vel, weights)(rot, trans, 0.8, 6.0)
    for out in (got, np_):
        assert out[0] == pytest.approx(ref[0], rel=1e-5)
        assert out[1] == pytest.approx(ref[1], rel=1e-5, abs=1e-9)
        scale = np.abs(ref[2]).max()
        np.testing.assert_allclose(out[2], ref[2], atol=1e-4 * scale)
        np.testing.assert_allclose(out[3], ref[3], atol=1e-4 * np.abs(ref[3]).max())


def test_reference_torch_energy_and_gradient_match_the_fast_ones():
    rng = np.random.default_rng(3)
    points, rest, vel, weights = problem(rng, frames=30, n=50, weighted=True)
    basis, controls = spline_controls(rng, 30, spans=5)
    objective = ControlObjective(basis, NumpyEnergy(points, rest, vel, weights, dtype=np.float64), 0.5, 4.0)
    value, grad = objective(controls.ravel())
    model = TorchModel(points, rest, vel, weights)
    q = torch.tensor(controls, dtype=torch.float32, requires_grad=True)
    e = model.energy(torch.tensor(basis.toarray(), dtype=torch.float32), q, 0.5, 4.0)
    e.backward()
    assert float(e.detach()) == pytest.approx(value, rel=1e-5)
    np.testing.assert_allclose(q.grad.numpy().ravel(), grad, atol=2e-3 * np.abs(grad).max())


def test_rebasing_changes_neither_energy_nor_gradient():
    rng = np.random.default_rng(4)
    points, rest, vel, weights = problem(rng, weighted=True)
    rot, trans = transforms(rng, len(points))
    base_rot, base_trans = transforms(rng, len(points), spread=0.5)
    plain = NumpyEnergy(points, rest, vel, weights, dtype=np.float64)
    moved = NumpyEnergy(points, rest, vel, weights, dtype=np.float64)
    moved.rebase(base_rot, base_trans * 10)
    a, b = plain(rot, trans, 0.5, 4.0), moved(rot, trans, 0.5, 4.0)
    assert b[0] + b[1] == pytest.approx(a[0] + a[1], rel=1e-12)
    np.testing.assert_allclose(b[2], a[2], atol=1e-9 * np.abs(a[2]).max())
    np.testing.assert_allclose(b[3], a[3], atol=1e-9 * np.abs(a[3]).max())
    if runtime.available():
        from facedyn.stabilize.opencl import OpenCLEnergy

        cl = OpenCLEnergy(points.astype(np.float32), rest.astype(np.float32), vel, weights)
        cl.rebase(base_rot, base_trans * 10)
        c = cl(rot, trans, 0.5, 4.0)
        assert c[0] + c[1] == pytest.approx(a[0] + a[1], rel=1e-5)
        np.testing.assert_allclose(c[2], a[2], atol=1e-4 * np.abs(a[2]).max())
