"""The ground-truth tissue simulator: exactness, physics, numerics and input checks.

Every test builds its own mesh (a face-sized patch of a sphere in front of the skull
origin) and its own skull motion (smooth sinusoids), so nothing here depends on the rig
or motion modules.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.integrate import solve_ivp

from facedyn.geometry import mesh, quaternion
from facedyn.sim.tissue import SimulationDiverged, SimulationResult, TissueParams, simulate

FPS = 120.0


def face_patch(n: int = 24, size: float = 12.0, radius: float = 10.0):
    """(points, triangles, rigid weights): an n x n grid on a sphere cap facing +Z, held on
    its border (weight 1) and easing to fully soft (weight 0) over the inner half."""
    s = np.linspace(-size / 2, size / 2, n)
    x, y = np.meshgrid(s, s, indexing="ij")
    points = np.stack([x.ravel(), y.ravel(), np.sqrt(radius**2 + size**2 - x.ravel() ** 2 - y.ravel() ** 2)], axis=1)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    triangles = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    ring = np.maximum(np.abs(x), np.abs(y)).ravel() / (size / 2)
    t = np.clip((ring - 0.5) / 0.45, 0.0, 1.0)
    return points, triangles, t * t * (3 - 2 * t)


def envelope(times: np.ndarray, ramp: float = 0.25, stop: float | None = None, fade: float = 0.1) -> np.ndarray:
    """0 -> 1 over `ramp` s (C2 quintic), back to 0 over `fade` s ending at `stop`."""
    def smooth(u):
        u = np.clip(u, 0.0, 1.0)
        return u**3 * (10 - 15 * u + 6 * u * u)

    env = smooth(times / ramp)
    return env if stop is None else env * smooth((stop - times) / fade)


def sinusoid(frames: int, hz: float, amplitude: float, axis=(0.0, 1.0, 0.0), **env):
    """Skull translating along `axis` (cm), identity orientation."""
    t = np.arange(frames) / FPS
    translate = (amplitude * envelope(t, **env) * np.sin(2 * np.pi * hz * t))[:, None] * np.asarray(axis, float)
    return translate, quaternion.identity((frames,))


def rocking(frames: int, hz: float, degrees: float, axis=(0.0, 1.0, 0.0), **env):
    """Skull turning about `axis` through its origin, no translation."""
    t = np.arange(frames) / FPS
    angle = np.radians(degrees) * envelope(t, **env) * np.sin(2 * np.pi * hz * t)
    return np.zeros((frames, 3)), quaternion.from_axis_angle(np.tile(np.asarray(axis, float), (frames, 1)), angle)


def held(points: np.ndarray, frames: int) -> np.ndarray:
    return np.repeat(points[None], frames, axis=0)


def stretch(points: np.ndarray, amount: float) -> np.ndarray:
    """An 'expression': the centre of the patch (r < 2.5 cm) stretched by `amount`,
    easing back to the neutral at r = 5 cm."""
    d = points[:, :2]
    t = np.clip((np.linalg.norm(d, axis=1) - 2.5) / 2.5, 0, 1)
    fall = 1 - t * t * (3 - 2 * t)
    out = points.copy()
    out[:, :2] += amount * fall[:, None] * d
    return out


def talking(points: np.ndarray, frames: int, amount: float = 0.15, hz: float = 1.5) -> np.ndarray:
    """A changing expression: the centre stretching and relaxing."""
    s = 0.5 * (1 - np.cos(2 * np.pi * hz * np.arange(frames) / FPS))
    return np.stack([stretch(points, amount * k) for k in s])


def peak(offsets: np.ndarray) -> float:
    return float(np.linalg.norm(offsets, axis=-1).max())


@pytest.fixture(scope="module")
def patch():
    return face_patch()


def test_still_skull_is_exact_rest_for_any_expression(patch):
    points, tris, weights = patch
    frames = 240
    y = talking(points, frames, amount=0.3)
    tilted = quaternion.from_axis_angle(np.array([1.0, 0.3, 0.0]), 0.4)
    orient = np.tile(tilted, (frames, 1))
    translate = np.tile([3.0, -40.0, 7.0], (frames, 1))
    result = simulate(y, tris, translate, orient, FPS, rigid_weights=weights, neutral=points)
    assert isinstance(result, SimulationResult)
    assert np.array_equal(result.points, y)  # exactly: no drift, no lag, no sag
    assert not np.any(result.offsets)
    assert result.stiffness_gain.max() > 1.2  # the expression did change the stiffness
    # constant velocity is zero acceleration too (exact up to the spline's round-off)
    moving = translate + np.arange(frames)[:, None] * np.array([0.5, 0.2, -0.1])
    drifting = simulate(y, tris, moving, orient, FPS, rigid_weights=weights, neutral=points)
    assert peak(drifting.offsets) < 1e-9


def test_float32_in_float32_out_and_exact(patch):
    points, tris, weights = patch
    y = talking(points, 60).astype(np.float32)
    result = simulate(y, tris, np.zeros((60, 3)), quaternion.identity((60,)), FPS, rigid_weights=weights)
    assert result.points.dtype == np.float32 and result.offsets.dtype == np.float32
    assert np.array_equal(result.points, y)


def test_isolated_vertices_match_the_damped_oscillator():
    """With no membrane and no bone, each vertex is the textbook base-excited oscillator."""
    points, tris, _ = face_patch(n=6)
    params = TissueParams(coupling_cm=1e-6, strain_stiffening=0.0)
    w0 = 2 * np.pi * params.soft_hz
    a, b = params.rayleigh()
    assert np.isclose(a / (2 * w0) + b * w0 / 2, params.damping_ratio)  # the stated damping ratio
    for hz in (2.0, 8.0, 11.0):
        frames = 480
        translate, orient = sinusoid(frames, hz, 0.2)
        result = simulate(held(points, frames), tris, translate, orient, FPS, params)
        w = 2 * np.pi * hz
        expected = 0.2 * w**2 / abs(w0**2 - w**2 + 1j * w * (a + b * w0**2))
        steady = np.abs(result.offsets[300:, :, 1]).max()
        assert steady == pytest.approx(expected, rel=0.01)
        assert np.abs(result.offsets[300:, :, [0, 2]]).max() < 1e-9 * expected


def test_springs_stiffer_along_the_normal_are_two_oscillators():
    """normal_ratio r: with no membrane each vertex is the base-excited oscillator at r w0
    along its neutral's normal (Rayleigh damping a + b (r w0)^2 there) and at w0 along the skin."""
    points, tris, _ = face_patch(n=6)
    ratio = 2.5
    params = TissueParams(coupling_cm=1e-6, strain_stiffening=0.0, normal_ratio=ratio)
    a, b = params.rayleigh()
    normals = mesh.vertex_normals(points, tris)
    frames, hz = 480, 8.0
    translate, orient = sinusoid(frames, hz, 0.2)
    result = simulate(held(points, frames), tris, translate, orient, FPS, params)
    w = 2 * np.pi * hz
    shake = np.array([0.0, 1.0, 0.0])
    along = normals @ shake  # the shake's share along each normal
    steady = result.offsets[300:]
    for w_i, share, part in ((ratio * 2 * np.pi * params.soft_hz, np.abs(along), np.einsum("fni,ni->fn", steady, normals)),
                             (2 * np.pi * params.soft_hz, np.sqrt(1 - along**2), None)):
        if part is None:  # along the skin: what is left after the normal part
            part = np.linalg.norm(steady - np.einsum("fn,ni->fni", np.einsum("fni,ni->fn", steady, normals), normals), axis=2)
        expected = 0.2 * w**2 * share / abs(w_i**2 - w**2 + 1j * w * (a + b * w_i**2))
        assert np.abs(part).max(axis=0) == pytest.approx(expected, rel=0.01, abs=1e-9)
    assert np.abs(np.einsum("fni,ni->fn", steady, normals)).max() < 0.3 * np.abs(steady[..., 1]).max()


def test_expression_inertia_loads_the_tissue_as_a_moving_base_would():
    """A rest shape that moves as a whole, still skull: with expression_inertia e its
    acceleration loads the tissue like a skull moving the other way, e times. y'' is the
    frames' central difference, the skull's a cubic spline's: for a sinusoid their ratio is
    (4 + 2 cos wh) / 6."""
    points, tris, _ = face_patch(n=6)
    frames, hz = 480, 8.0
    translate, _ = sinusoid(frames, hz, 0.2)
    y = held(points, frames) + translate[:, None, :]
    still = (np.zeros((frames, 3)), quaternion.identity((frames,)))
    base = TissueParams(coupling_cm=1e-6, strain_stiffening=0.0)
    moving_skull = simulate(held(points, frames), tris, translate, still[1], FPS, base)
    difference = (4 + 2 * np.cos(2 * np.pi * hz / FPS)) / 6
    for e in (0.0, 0.5, 1.0):
        result = simulate(y, tris, *still, FPS, replace(base, expression_inertia=e))
        expected = e * difference * np.abs(moving_skull.offsets[300:, :, 1]).max()
        assert np.abs(result.offsets[300:, :, 1]).max() == pytest.approx(expected, rel=0.01, abs=1e-12)
        assert np.abs(result.offsets[300:, :, [0, 2]]).max() <= 1e-9 * max(expected, 1.0)


def test_thinner_tissue_rings_higher():
    """depth_variation raises the soft spring frequency by exp(depth_variation * t), t in (0, 1),
    and leaves bone_hz on the bone."""
    points, _, weights = face_patch()
    plain = TissueParams(layout_seed=3)
    thin = replace(plain, depth_variation=1.2)
    ratio = thin.attachment_hz(weights, points) / plain.attachment_hz(weights, points)
    soft = weights == 0
    assert np.all(ratio[soft] > 1.0) and np.all(ratio[soft] < np.exp(1.2)) and np.ptp(ratio[soft]) > 0.3
    assert np.allclose(ratio[weights == 1], 1.0)
    with pytest.raises(ValueError, match="neutral points"):
        thin.attachment_hz(weights)


@pytest.mark.slow  # simulates seconds of springs several times over
def test_inertial_loads_match_an_independent_integration():
    """Translation, rotation (Euler, Coriolis, centrifugal) and turning gravity at once,
    against scipy's adaptive integrator on the skull-frame equations of a few vertices."""
    points = np.array([[0.0, 0.0, 10.0], [0.1, 0.0, 10.0], [0.0, 0.1, 10.0],
                       [5.0, 3.0, 8.0], [5.1, 3.0, 8.0], [5.0, 3.1, 8.0]])
    tris = np.array([[0, 1, 2], [3, 4, 5]])
    params = TissueParams(coupling_cm=1e-6, strain_stiffening=0.0)
    frames = 240
    times = np.arange(frames) / FPS
    axis = np.array([0.3, 1.0, 0.2]) / np.linalg.norm([0.3, 1.0, 0.2])

    def angle(t):
        return 0.3 * envelope(np.asarray(t), 0.4) * np.sin(2 * np.pi * 3.0 * t)

    def origin(t):
        e = envelope(np.asarray(t), 0.4)
        return np.stack([0.5 * e * np.sin(2 * np.pi * 5 * t), 0.3 * e * np.cos(2 * np.pi * 4 * t) - 0.3 * e, 0 * t], -1)

    orient = quaternion.from_axis_angle(np.tile(axis, (frames, 1)), angle(times))
    result = simulate(held(points, frames), tris, origin(times), orient, FPS, params)

    w0 = 2 * np.pi * params.soft_hz
    a, b = params.rayleigh()
    g = np.array([0.0, -params.gravity_cm_s2, 0.0])
    d = 1e-4

    def rhs(t, s):
        u, v = s[:18].reshape(6, 3), s[18:].reshape(6, 3)
        omega = axis * (angle(t + d) - angle(t - d)) / (2 * d)
        alpha = axis * (angle(t + d) - 2 * angle(t) + angle(t - d)) / d**2
        rot = quaternion.to_matrix(quaternion.from_axis_angle(axis, angle(t)))
        a0 = rot.T @ ((origin(t + d) - 2 * origin(t) + origin(t - d)) / d**2)
        r = points + u
        acc = (-w0**2 * u - (a + b * w0**2) * v + rot.T @ g - g - a0
               - np.cross(alpha, r) - 2 * np.cross(omega, v) - np.cross(omega, np.cross(omega, r)))
        return np.concatenate([v.ravel(), acc.ravel()])

    reference = solve_ivp(rhs, (0, times[-1]), np.zeros(36), t_eval=times, rtol=1e-8, atol=1e-10, max_step=1 / 240)
    expected = reference.y[:18].T.reshape(frames, 6, 3)
    assert peak(expected) > 0.3
    assert np.abs(result.offsets - expected).max() < 0.005 * peak(expected)


def test_offsets_are_linear_in_the_motion(patch):
    points, tris, weights = patch
    frames = 240
    runs = []
    for scale in (1.0, 2.0):
        translate, _ = sinusoid(frames, 11.0, 0.1 * scale)
        _, orient = rocking(frames, 11.0, 0.3 * scale, axis=(1.0, 0.0, 0.0))
        runs.append(simulate(held(points, frames), tris, translate, orient, FPS, rigid_weights=weights).offsets)
    ratio = np.linalg.norm(runs[1]) / np.linalg.norm(runs[0])
    assert ratio == pytest.approx(2.0, rel=0.1)
    np.testing.assert_allclose(runs[1], 2 * runs[0], atol=0.01 * np.abs(runs[1]).max())


def test_stiffness_gain_is_the_mean_edge_strain(patch):
    points, tris, weights = patch
    rng = np.random.default_rng(1)
    frames = np.stack([points, 1.1 * points, points + rng.normal(scale=0.05, size=points.shape), 1.1 * points])
    result = simulate(frames, tris, np.zeros((4, 3)), quaternion.identity((4,)), FPS,
                      TissueParams(strain_stiffening=4.0), neutral=points)
    gain = result.stiffness_gain
    np.testing.assert_allclose(gain[0], 1.0, atol=1e-5)  # float32 edge lengths
    np.testing.assert_allclose(gain[1], 1.4, rtol=1e-5)  # every edge 10 % longer
    edges = mesh.unique_edges(tris)
    rest = np.linalg.norm(points[edges[:, 1]] - points[edges[:, 0]], axis=1)
    strain = np.abs(np.linalg.norm(frames[2][edges[:, 1]] - frames[2][edges[:, 0]], axis=1) / rest - 1)
    total = np.bincount(edges.ravel(), np.repeat(strain, 2), len(points))
    np.testing.assert_allclose(gain[2], 1 + 4.0 * total / np.bincount(edges.ravel(), minlength=len(points)), rtol=1e-5)
    np.testing.assert_array_equal(gain[3], gain[1])


def test_a_stretched_expression_jiggles_less(patch):
    points, tris, weights = patch
    frames = 240
    translate, orient = sinusoid(frames, 6.0, 0.3)
    region = np.linalg.norm(points[:, :2], axis=1) < 2.0
    rms = {}
    for amount in (0.0, 0.15):
        result = simulate(held(stretch(points, amount), frames), tris, translate, orient, FPS,
                          rigid_weights=weights, neutral=points)
        rms[amount] = np.sqrt(np.mean(result.offsets[120:, region] ** 2))
        if amount:
            assert result.stiffness_gain[:, region].min() > 1.3
    assert rms[0.15] < 0.85 * rms[0.0]


def test_jiggle_dies_out_within_half_a_second(patch):
    points, tris, weights = patch
    frames = 240
    stop = 1.0
    translate, orient = sinusoid(frames, 8.0, 0.3, stop=stop)
    result = simulate(held(points, frames), tris, translate, orient, FPS, rigid_weights=weights)
    magnitude = np.linalg.norm(result.offsets, axis=-1).max(axis=1)
    at_stop = magnitude[int((stop - 0.15) * FPS):int(stop * FPS) + 1].max()
    after = magnitude[int((stop + 0.5) * FPS):].max()
    assert at_stop > 0.1
    assert after < 0.1 * at_stop


def test_turning_alone_moves_the_tissue(patch):
    points, tris, weights = patch
    frames = 240
    params = TissueParams(gravity_cm_s2=0.0)
    translate, orient = rocking(frames, 4.0, 3.0, axis=(0.0, 1.0, 0.0))  # shaking "no"
    result = simulate(held(points, frames), tris, translate, orient, FPS, params, rigid_weights=weights)
    u = result.offsets[:, weights == 0]
    assert peak(u) > 0.05
    # the face sits at +Z, so yaw accelerations push it sideways (Euler load -alpha x r)
    assert np.abs(u[..., 0]).max() > 5 * np.abs(u[..., 1]).max()


def test_steady_spin_pushes_outward_by_the_centrifugal_load():
    points, tris, _ = face_patch(n=6)
    params = TissueParams(coupling_cm=1e-6, strain_stiffening=0.0, gravity_cm_s2=0.0)
    frames, spin = 360, 4.0  # rad/s about Y, reached smoothly within 0.5 s
    t = np.arange(frames) / FPS
    u = np.clip(t / 0.5, 0, 1)  # angular speed spin * smoothstep(u); its integral:
    angle = spin * np.where(t < 0.5, 0.5 * (2.5 * u**4 - 3 * u**5 + u**6), t - 0.25)
    orient = quaternion.from_axis_angle(np.tile([0.0, 1.0, 0.0], (frames, 1)), angle)
    result = simulate(held(points, frames), tris, np.zeros((frames, 3)), orient, FPS, params)
    radial = points * np.array([1.0, 0.0, 1.0])
    w0 = 2 * np.pi * params.soft_hz
    expected = spin**2 * radial / (w0**2 - spin**2)  # u'' = 0 = -w0^2 u + spin^2 (r + u)
    np.testing.assert_allclose(result.offsets[-1], expected, atol=0.01 * np.abs(expected).max())


def test_sideways_motion_gives_sideways_offsets(patch):
    points, tris, weights = patch
    frames = 360
    translate, orient = sinusoid(frames, 2.0, 2.0, axis=(1.0, 0.0, 0.0))
    result = simulate(held(points, frames), tris, translate, orient, FPS, rigid_weights=weights)
    u = result.offsets[:, weights == 0]
    assert np.abs(u[..., 0]).max() > 20 * np.abs(u[..., 1:]).max()
    # below resonance the tissue lags like a pendulum: offset against the acceleration
    accel = np.gradient(np.gradient(translate[:, 0], 1 / FPS), 1 / FPS)
    assert np.corrcoef(u[60:, :, 0].mean(axis=1), -accel[60:])[0, 1] > 0.9


def test_gravity_sags_by_the_turned_weight():
    points, tris, _ = face_patch(n=6)
    params = TissueParams(coupling_cm=1e-6, strain_stiffening=0.0)
    frames = 360
    t = np.arange(frames) / FPS
    pitch = np.radians(30.0) * envelope(t, ramp=1.0)  # nod down 30 degrees, then hold
    orient = quaternion.from_axis_angle(np.tile([1.0, 0.0, 0.0], (frames, 1)), pitch)
    result = simulate(held(points, frames), tris, np.zeros((frames, 3)), orient, FPS, params)
    g = np.array([0.0, -params.gravity_cm_s2, 0.0])
    turned = quaternion.to_matrix(orient[-1]).T @ g - g  # gravity change seen from the skull
    w0 = 2 * np.pi * params.soft_hz
    np.testing.assert_allclose(result.offsets[-1], np.broadcast_to(turned / w0**2, points.shape), rtol=0.01, atol=1e-6)
    # that sag is the pose's static shape, not dynamics: exactly turned / w0^2 at every
    # frame, and once the head is held nothing dynamic is left
    seen = np.einsum("fji,j->fi", quaternion.to_matrix(orient), g) - g
    np.testing.assert_allclose(result.gravity_sag, np.broadcast_to(seen[:, None] / w0**2, result.offsets.shape), rtol=1e-5, atol=1e-9)
    assert np.abs(result.dynamics[-60:]).max() < 0.01 * np.abs(result.offsets[-1]).max()
    assert np.abs(result.dynamics[:120]).max() > 1e-3 * np.abs(result.offsets[-1]).max()  # the nod itself jiggles a little


@pytest.mark.parametrize("normal_ratio", [1.0, 2.5])
def test_gravity_sag_is_the_static_solution_under_any_expression(patch, normal_ratio):
    """K(t) s(t) = M (g(t) - g(0)) with the membrane coupling, the expression's stiffening and
    springs stiffer along the normal (K_i = M_i w_i^2 gain_i (I + (ratio^2 - 1) n_i n_i^T))."""
    points, tris, weights = patch
    frames = 90
    t = np.arange(frames) / FPS
    orient = quaternion.from_axis_angle(np.tile([0.6, 0.0, 0.8], (frames, 1)), np.radians(40.0) * t)
    y = talking(points, frames)
    params = TissueParams(normal_ratio=normal_ratio)
    result = simulate(y, tris, np.zeros((frames, 3)), orient, FPS, params, rigid_weights=weights, neutral=points)
    free = weights < 1.0
    mass = mesh.vertex_areas(points, tris)[free]
    lap = mesh.cotangent_laplacian(points, tris, nonnegative=True)[free][:, free]
    spring = (2 * np.pi * params.attachment_hz(weights[free])) ** 2
    g = np.array([0.0, -params.gravity_cm_s2, 0.0])
    turned = np.einsum("fji,j->fi", quaternion.to_matrix(orient), g) - quaternion.to_matrix(orient[0]).T @ g
    normals = mesh.vertex_normals(points, tris)[free]
    for f in (0, 45, 89):
        sag = result.gravity_sag[f, free]
        along = normals * np.sum(normals * sag, axis=1, keepdims=True)
        bone = (mass * spring * result.stiffness_gain[f, free])[:, None] * (sag + (normal_ratio**2 - 1) * along)
        membrane = (params.coupling_cm * 2 * np.pi * params.soft_hz) ** 2 * lap @ sag
        residual = bone + membrane - mass[:, None] * turned[f]
        assert np.abs(residual).max() <= 1e-5 * np.abs(mass[:, None] * turned[f]).max() + 1e-12
    assert not np.any(result.gravity_sag[:, ~free]) and not np.any(result.gravity_sag[0])
    assert len(np.unique(result.stiffness_gain[:, free], axis=0)) > 10  # the expression really changes


def test_offsets_are_smooth_fields(patch):
    points, tris, weights = patch
    frames = 240
    translate, orient = sinusoid(frames, 11.0, 0.2)
    _, rock = rocking(frames, 7.0, 1.0, axis=(1.0, 0.0, 0.0))
    result = simulate(talking(points, frames), tris, translate, rock, FPS, rigid_weights=weights, neutral=points)
    lap = mesh.cotangent_laplacian(points, tris)

    def roughness(field):
        return np.einsum("nc,nc->", field, lap @ field) / np.einsum("nc,nc->", field, field)

    frame = int(np.argmax(np.linalg.norm(result.offsets, axis=(1, 2))))
    u = result.offsets[frame]
    noise = np.random.default_rng(0).normal(size=u.shape) * (weights < 1)[:, None]
    assert roughness(u) < 0.05 * roughness(noise)
    edges = mesh.unique_edges(tris)
    cosine = np.einsum("ec,ec->e", u[edges[:, 0]], u[edges[:, 1]]) / (
        np.linalg.norm(u[edges[:, 0]], axis=1) * np.linalg.norm(u[edges[:, 1]], axis=1) + 1e-12)
    moving = (weights[edges] < 1).all(axis=1)
    assert np.median(cosine[moving]) > 0.99


def test_one_step_per_frame_agrees_with_finer_steps(patch):
    points, tris, weights = patch
    frames = 240
    translate, _ = sinusoid(frames, 11.0, 0.2)
    _, orient = rocking(frames, 5.0, 2.0, axis=(0.3, 1.0, 0.0))
    y = talking(points, frames, amount=0.25)
    runs = {s: simulate(y, tris, translate, orient, FPS, TissueParams(substeps=s), rigid_weights=weights,
                        neutral=points).offsets for s in (1, 2, 8)}
    scale = np.abs(runs[8]).max()
    assert np.abs(runs[1] - runs[8]).max() < 0.02 * scale
    assert np.abs(runs[2] - runs[8]).max() < 0.005 * scale


@pytest.mark.slow  # simulates seconds of springs several times over
@pytest.mark.parametrize("normal_ratio, saving", [(1.0, 5), (2.5, 2), (4.0, 1)])
def test_stiffness_drift_correction_matches_refactorizing(patch, normal_ratio, saving):
    """The explicit gain-drift correction stays as accurate as refactorizing every step; a
    spring stiffer along the normal (160 Hz here on the bone) may drift less, so it saves less."""
    points, tris, weights = patch
    frames = 240
    translate, orient = sinusoid(frames, 8.0, 0.3)
    y = talking(points, frames, amount=0.3, hz=2.0)
    strong = TissueParams(strain_stiffening=10.0, normal_ratio=normal_ratio)
    lazy = simulate(y, tris, translate, orient, FPS, strong, rigid_weights=weights, neutral=points)
    eager = simulate(y, tris, translate, orient, FPS, replace(strong, refactor_tolerance=1e-9),
                     rigid_weights=weights, neutral=points)
    assert eager.factorizations > 200 and lazy.factorizations < eager.factorizations / saving
    assert np.abs(lazy.offsets - eager.offsets).max() < 0.01 * np.abs(eager.offsets).max()


@pytest.mark.slow  # simulates seconds of springs several times over
def test_a_held_expression_on_springs_stiff_along_the_normal_stays_stable():
    """An expression eased in and then held leaves the factorization's gain behind. On the
    built-in face with springs 3.8x stiffer along the normal (TissueParams.random(13), the
    training corpus's jaw_open_dance take) a lasting explicit correction grew without bound
    (metres by the end); a held gain is refactorized: the take matches refactorizing every step."""
    from facedyn.sim.corpus import TakeSpec, simulate_take
    from facedyn.sim.default_face import default_face

    rig = default_face()
    params = TissueParams.random(13)
    assert params.normal_ratio > 3.5
    spec = TakeSpec("jaw_open_dance", "dance", "jaw_open", duration_s=2.0, seed=13)
    lazy = simulate_take(rig, spec, params).offsets
    eager = simulate_take(rig, spec, replace(params, refactor_tolerance=1e-9)).offsets
    assert np.abs(lazy - eager).max() < 0.01 * np.abs(eager).max() < 0.1


@pytest.mark.slow  # simulates seconds of a creeping expression on stiff springs (about 20 s)
def test_an_expression_that_never_quite_holds_still_stays_stable_on_springs_stiff_along_the_normal():
    """The held expression above, creeping by 1e-4 of a weight as a Live Link curve does: its gain
    moves on every frame but drifts less than the tolerance, so the correction stayed explicit
    for seconds and diverged (frame 203); the stability bound (EXPLICIT_LIMIT) refactorizes it,
    at one step per frame, matching refactorizing every step."""
    from facedyn.sim.corpus import TakeSpec, expression_weights, skull_motion
    from facedyn.sim.default_face import default_face

    rig = default_face()
    params = TissueParams.random(13)
    spec = TakeSpec("jaw_open_dance", "dance", "jaw_open", duration_s=2.0, seed=13)
    trajectory = skull_motion(spec)
    weights = expression_weights(rig, spec, trajectory.frame_count)
    t = np.arange(trajectory.frame_count) / spec.fps
    weights[:, rig.shape_index("jawOpen")] += 1e-4 * np.sin(2 * np.pi * 0.7 * t) * (t > 0.3)
    args = (rig.evaluate(weights), rig.topology.triangles(), trajectory.translate, trajectory.orient, spec.fps)
    lazy = simulate(*args, params, rigid_weights=rig.rigid_weights, neutral=rig.neutral)
    eager = simulate(*args, replace(params, refactor_tolerance=1e-9), rigid_weights=rig.rigid_weights, neutral=rig.neutral)
    assert lazy.substeps == 1 and lazy.factorizations < eager.factorizations / 4
    assert np.abs(lazy.offsets - eager.offsets).max() < 0.01 * np.abs(eager.offsets).max() < 0.1


def test_the_rigid_region_stays_exactly_on_the_bone(patch):
    points, tris, weights = patch
    frames = 120
    translate, orient = sinusoid(frames, 11.0, 0.3)
    y = talking(points, frames)
    result = simulate(y, tris, translate, orient, FPS, rigid_weights=weights, neutral=points)
    bone = weights == 1.0
    assert bone.sum() > 50 and peak(result.offsets[:, ~bone]) > 0.05
    assert not np.any(result.offsets[:, bone])
    assert np.array_equal(result.points[:, bone], y[:, bone])
    # the attachment stiffens toward the bone: soft tissue at soft_hz, bone_hz at weight 1
    params = TissueParams()
    assert result.attachment_hz.min() == pytest.approx(params.soft_hz)
    assert result.attachment_hz.max() == pytest.approx(params.bone_hz)


def test_tracking_noise_is_seeded_gaussian_on_the_points_only(patch):
    points, tris, weights = patch
    frames = 120
    translate, orient = sinusoid(frames, 8.0, 0.2)
    y = held(points, frames)
    clean = simulate(y, tris, translate, orient, FPS, rigid_weights=weights)
    noisy = simulate(y, tris, translate, orient, FPS, noise_cm=0.05, seed=3, rigid_weights=weights)
    np.testing.assert_array_equal(noisy.offsets, clean.offsets)  # the truth is noise-free
    noise = noisy.points - (y + noisy.offsets)
    assert noise.std() == pytest.approx(0.05, rel=0.02)
    assert abs(noise.mean()) < 0.002
    assert abs(np.corrcoef(noise[..., 0].ravel(), noise[..., 1].ravel())[0, 1]) < 0.02
    again = simulate(y, tris, translate, orient, FPS, noise_cm=0.05, seed=3, rigid_weights=weights)
    other = simulate(y, tris, translate, orient, FPS, noise_cm=0.05, seed=4, rigid_weights=weights)
    np.testing.assert_array_equal(again.points, noisy.points)
    assert not np.array_equal(other.points, noisy.points)


def test_default_magnitudes_are_the_papers(patch):
    """About +-5 mm on the fastest platform (11 Hz, 2 mm), 1-2 mm walking (0.4 g at 2 Hz)."""
    points, tris, weights = patch
    frames = 360
    platform = simulate(held(points, frames), tris, *sinusoid(frames, 11.0, 0.2, ramp=0.5), FPS, rigid_weights=weights)
    assert 0.35 < peak(platform.offsets) < 0.7
    bob = 0.4 * 981.0 / (2 * np.pi * 2.0) ** 2  # vertical bob whose acceleration peaks at 0.4 g
    walking = simulate(held(points, frames), tris, *sinusoid(frames, 2.0, bob, ramp=0.5), FPS, rigid_weights=weights)
    assert 0.1 < peak(walking.offsets) < 0.25


def test_degenerate_takes(patch):
    points, tris, weights = patch
    one = simulate(points[None], tris, np.zeros((1, 3)), quaternion.identity((1,)), FPS)
    assert np.array_equal(one.points, points[None]) and not np.any(one.offsets)
    translate, orient = sinusoid(30, 11.0, 0.3)
    bone = simulate(held(points, 30), tris, translate, orient, FPS, rigid_weights=np.ones(len(points)))
    assert not np.any(bone.offsets) and bone.factorizations == 0


@pytest.mark.parametrize(
    "change, message",
    [
        (dict(rest_shapes=np.zeros((10, 5, 2))), "rest_shapes must be"),
        (dict(skull_translate=np.zeros((9, 3))), "skull_translate must be"),
        (dict(skull_orient=np.zeros((10, 3))), "skull_orient must be"),
        (dict(skull_orient=np.zeros((10, 4))), "zero quaternion"),
        (dict(fps=0.0), "fps must be positive"),
        (dict(fps=-120.0), "fps must be positive"),
        (dict(triangles=np.array([[0, 1, 9]])), "indices must lie"),
        (dict(triangles=np.array([[0.0, 1.0, 2.0]])), "integer"),
        (dict(rigid_weights=np.full(5, 1.5)), "rigid_weights must lie"),
        (dict(rigid_weights=np.zeros(4)), "rigid_weights must be"),
        (dict(neutral=np.zeros((4, 3))), "neutral must be"),
        (dict(noise_cm=-0.1), "noise_cm"),
        (dict(skull_translate=np.full((10, 3), np.nan)), "non-finite"),
    ],
)
def test_bad_input_is_a_clear_error(change, message):
    rng = np.random.default_rng(0)
    args = dict(rest_shapes=rng.normal(size=(10, 5, 3)), triangles=np.array([[0, 1, 2], [2, 3, 4]]),
                skull_translate=np.zeros((10, 3)), skull_orient=quaternion.identity((10,)), fps=120.0)
    args.update(change)
    kwargs = {k: args.pop(k) for k in ("rigid_weights", "neutral", "noise_cm") if k in args}
    with pytest.raises(ValueError, match=message):
        simulate(**args, **kwargs)


@pytest.mark.parametrize(
    "params, message",
    [
        (dict(soft_hz=0.0), "soft_hz"),
        (dict(bone_hz=5.0), "bone_hz"),
        (dict(damping_ratio=-0.1), "damping_ratio"),
        (dict(strain_stiffening=-1.0), "strain_stiffening"),
        (dict(substeps=0), "substeps"),
        (dict(substeps=1.5), "substeps"),
        (dict(refactor_tolerance=0.0), "refactor_tolerance"),
        (dict(depth_variation=-0.5), "depth_variation"),
        (dict(expression_inertia=1.5), "expression_inertia"),
        (dict(normal_ratio=0.5), "normal_ratio"),
    ],
)
def test_bad_params_are_a_clear_error(params, message):
    with pytest.raises(ValueError, match=message):
        TissueParams(**params)


def test_substeps_double_up_to_the_finest():
    from facedyn.sim.tissue import MAX_SUBSTEPS, substep_ladder

    assert substep_ladder(1) == [1, 2, 4, 8, 16] and MAX_SUBSTEPS == 16
    assert substep_ladder(3) == [3, 6, 12] and substep_ladder(32) == [32]


def test_a_diverging_integration_is_retried_at_finer_steps(patch, monkeypatch):
    """Springs 4x stiffer along the normal (160 Hz on the bone) whose gain drift is never
    refactorized (no tolerance, no stability bound) diverge at one step per frame (the explicit
    correction feeds a stiff mode): the safety net for what a bound misses integrates the take
    again at finer steps, and it matches refactorizing every step."""
    from facedyn.sim import tissue

    monkeypatch.setattr(tissue, "EXPLICIT_LIMIT", np.inf)
    points, tris, weights = patch
    frames = 120
    translate, orient = sinusoid(frames, 8.0, 0.3)
    y = talking(points, frames, amount=0.3, hz=2.0)
    params = TissueParams(strain_stiffening=10.0, normal_ratio=4.0, refactor_tolerance=100.0)
    retried = simulate(y, tris, translate, orient, FPS, params, rigid_weights=weights, neutral=points)
    eager = simulate(y, tris, translate, orient, FPS, replace(params, refactor_tolerance=1e-9), rigid_weights=weights, neutral=points)
    assert retried.substeps > 1 and eager.substeps == 1
    assert np.abs(retried.offsets - eager.offsets).max() < 0.01 * np.abs(eager.offsets).max()
    with pytest.raises(SimulationDiverged, match=r"diverged at frame \d+ \(.* s\) even at 2 steps per frame"):
        simulate(y, tris, translate, orient, FPS, replace(params, substeps=2), rigid_weights=weights, neutral=points,
                 max_substeps=2)


def test_a_vertex_beyond_what_tissue_does_is_a_divergence(patch, monkeypatch):
    """Offsets are bounded by MAX_DEFLECTION_CM (and the face's size): a take that exceeds it
    at every step size is an error naming the frame, not a take with a spike in it."""
    from facedyn.sim import tissue

    points, tris, weights = patch
    frames = 60
    translate, orient = sinusoid(frames, 8.0, 0.3)
    result = simulate(held(points, frames), tris, translate, orient, FPS, rigid_weights=weights, neutral=points)
    monkeypatch.setattr(tissue, "MAX_DEFLECTION_CM", 0.5 * float(np.abs(result.offsets).max()))
    with pytest.raises(SimulationDiverged, match=r"diverged at frame \d+ .* even at 4 steps per frame"):
        simulate(held(points, frames), tris, translate, orient, FPS, rigid_weights=weights, neutral=points, max_substeps=4)
