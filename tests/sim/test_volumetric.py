"""The second physics (facedyn.sim.volumetric): rest, invariance, statics, spectrum, energy.

Most tests use a flat slab of tissue (held on its border, uniform depth), where the
layer behaves as the one-dimensional shear layer its parameters are defined by, so the
checks are against closed forms; the last ones use the built-in face.
"""
from __future__ import annotations

import numpy as np
import pytest

from facedyn.geometry import quaternion
from facedyn.sim import tissue, volumetric
from facedyn.sim.volumetric import Layer, VolumetricParams, simulate

FPS = 120.0


def slab(n: int = 17, size: float = 16.0):
    """(points, triangles, rigid weights): a flat n x n grid in the xy plane, border held."""
    s = np.linspace(-size / 2, size / 2, n)
    x, y = np.meshgrid(s, s, indexing="ij")
    points = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    triangles = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    weights = (np.maximum(np.abs(x), np.abs(y)).ravel() >= size / 2 - 1e-9).astype(float)
    return points, triangles, weights


def flat(**overrides) -> VolumetricParams:
    """A uniform 1 cm layer, no spatial variation."""
    return VolumetricParams(**{"thickness_cm": 1.0, "bone_thickness_cm": 1.0, **overrides})


def push(frames: int, distance: float = 0.5, duration: float = 0.06, axis: int = 1, start: float = 0.1):
    """The skull moved by `distance` cm along `axis` in a quick minimum-jerk push, then held."""
    t = np.arange(frames) / FPS
    u = np.clip((t - start) / duration, 0.0, 1.0)
    translate = np.zeros((frames, 3))
    translate[:, axis] = distance * u**3 * (10 - 15 * u + 6 * u * u)
    return translate, quaternion.identity((frames,))


def held(points, frames):
    return np.repeat(points[None], frames, axis=0)


def peak_hz(signal: np.ndarray) -> float:
    """Frequency of the largest (zero-padded, Hann-windowed) spectrum peak, summed over columns."""
    signal = signal.reshape(len(signal), -1)
    signal = signal - signal.mean(axis=0)
    n = 16 * len(signal)
    power = (np.abs(np.fft.rfft(signal * np.hanning(len(signal))[:, None], n, axis=0)) ** 2).sum(axis=1)
    return float(np.fft.rfftfreq(n, 1 / FPS)[np.argmax(power)])


@pytest.fixture(scope="module")
def sheet():
    return slab()


def centre(points) -> int:
    return int(np.argmin(np.linalg.norm(points, axis=1)))


def test_still_skull_and_held_expression_stay_at_rest(sheet):
    points, tris, weights = sheet
    frames = 60
    tilted = np.tile(quaternion.from_axis_angle(np.array([1.0, 0.3, 0.0]), 0.4), (frames, 1))
    result = simulate(held(points, frames), tris, np.tile([3.0, -40.0, 7.0], (frames, 1)), tilted, FPS, flat(),
                      rigid_weights=weights)
    assert np.abs(result.offsets).max() < 1e-9
    assert not np.any(result.gravity_sag)
    assert np.array_equal(result.offsets[:, weights == 1], np.zeros_like(result.offsets[:, weights == 1]))


def test_rigid_translation_leaves_no_deformation_after_transients(sheet):
    """Galilean invariance: a push then a hold (and constant velocity) ring down to exactly nothing."""
    points, tris, weights = sheet
    frames = 360
    translate, orient = push(frames, distance=1.0, axis=0)
    translate += np.arange(frames)[:, None] * np.array([0.3, 0.1, -0.2])  # plus a constant velocity
    result = simulate(held(points, frames), tris, translate, orient, FPS, flat(damping_ratio=0.3), rigid_weights=weights)
    peak = np.abs(result.dynamics).max()
    assert peak > 0.05  # the push did deform the layer
    assert np.abs(result.dynamics[-30:]).max() < 1e-3 * peak


@pytest.mark.slow  # simulates the volumetric layer for seconds
def test_static_sag_matches_the_shear_layer_estimate(sheet):
    """A 6 degree roll turns gravity along the slab: the centre sags rho g h^2 / (2 mu),
    the dynamics settle onto that sag, and the sag is zero on the held border."""
    points, tris, weights = sheet
    frames = 300
    t = np.arange(frames) / FPS
    ramp = np.clip(t / 0.8, 0.0, 1.0)
    angle = np.radians(6.0) * ramp**3 * (10 - 15 * ramp + 6 * ramp**2)
    orient = quaternion.from_axis_angle(np.tile([0.0, 0.0, 1.0], (frames, 1)), angle)
    params = flat(damping_ratio=0.3)
    result = simulate(held(points, frames), tris, np.zeros((frames, 3)), orient, FPS, params, rigid_weights=weights)
    turn = np.radians(6.0)
    gravity_change = params.gravity_cm_s2 * np.array([-np.sin(turn), 1 - np.cos(turn)])  # skull-frame x, y
    estimate = params.density * gravity_change * params.thickness_cm**2 / (2 * params.shear_modulus)
    c = centre(points)
    # linear tetrahedra lock a little at Poisson 0.45: the slab is about 5 % stiffer than the estimate
    np.testing.assert_allclose(result.gravity_sag[-1, c, :2], estimate, rtol=0.08)
    np.testing.assert_allclose(result.offsets[-1, c], result.gravity_sag[-1, c], atol=1e-3 * np.abs(estimate).max())
    assert not np.any(result.gravity_sag[:, weights == 1])


@pytest.mark.slow  # simulates the volumetric layer for seconds
def test_newton_steps_find_the_sag_where_chord_iterations_stop_short(sheet, monkeypatch):
    """Where the chord iterations on the rest tangent do not converge (cut to one here; on a
    stiffened layer they can cycle), projected Newton steps from the same start find the same
    static equilibrium."""
    points, tris, weights = sheet
    frames = 20
    orient = quaternion.from_axis_angle(np.tile([0.0, 0.0, 1.0], (frames, 1)), np.radians(np.linspace(0.0, 40.0, frames)))
    args = (held(points, frames), tris, np.zeros((frames, 3)), orient, FPS, flat(nonlinearity=4.0))
    chord = simulate(*args, rigid_weights=weights).gravity_sag
    monkeypatch.setattr(volumetric, "_SAG_ITERATIONS", 1)
    newton = simulate(*args, rigid_weights=weights).gravity_sag
    assert np.abs(chord).max() > 0.01  # cm: a sag worth finding
    np.testing.assert_allclose(newton, chord, atol=1e-4)


def test_a_gravity_sag_that_does_not_converge_is_an_error(sheet, monkeypatch):
    """No static equilibrium within the chord iterations and the Newton steps is a
    SimulationDiverged, never a sag returned half-way (one of each here, where the slab needs several)."""
    points, tris, weights = sheet
    frames = 20
    orient = quaternion.from_axis_angle(np.tile([0.0, 0.0, 1.0], (frames, 1)), np.radians(np.linspace(0.0, 6.0, frames)))
    monkeypatch.setattr(volumetric, "_SAG_ITERATIONS", 1)
    monkeypatch.setattr(volumetric, "_NEWTON_ITERATIONS", 1)
    with pytest.raises(tissue.SimulationDiverged, match="gravity sag did not converge at frame 1"):
        simulate(held(points, frames), tris, np.zeros((frames, 3)), orient, FPS, flat(), rigid_weights=weights)


@pytest.mark.slow  # simulates the volumetric layer for seconds
def test_a_push_rings_down_at_the_stated_frequency(sheet):
    points, tris, weights = sheet
    frames = 300
    translate, orient = push(frames)
    c = centre(points)
    for hz in (5.0, 9.0):
        result = simulate(held(points, frames), tris, translate, orient, FPS, flat(soft_hz=hz, damping_ratio=0.05, nonlinearity=0.0),
                          rigid_weights=weights)
        measured = peak_hz(result.dynamics[30:, c, 1])
        assert measured == pytest.approx(hz, rel=0.1), (hz, measured)


@pytest.mark.slow  # simulates the volumetric layer for seconds
def test_energy_decays_at_the_damping_rate(sheet):
    """Newmark average acceleration conserves a linear layer's energy; Kelvin-Voigt
    viscosity takes it away at about 2 zeta omega per second."""
    points, tris, weights = sheet
    frames = 240
    translate, orient = push(frames, distance=0.1)
    rates = {}
    for zeta in (1e-4, 0.1):
        params = flat(damping_ratio=zeta, nonlinearity=0.0, gravity_cm_s2=0.0)
        result = simulate(held(points, frames), tris, translate, orient, FPS, params, rigid_weights=weights)
        layer = Layer(points, tris, weights, params)
        stiffness = layer.linear_stiffness(layer.shape, layer.volume)
        skin = layer.dof[layer.skin]
        # the skin's energy in the free layer: elastic from K (skin dofs only; the layer has no other free node)
        u = result.offsets[:, layer.vertices[layer.skin]].astype(np.float64)
        assert len(skin) == len(layer.free)
        v = np.gradient(u, 1 / FPS, axis=0)
        flat_u = np.zeros((frames, len(layer.free), 3))
        flat_u[:, skin] = u
        elastic = 0.5 * np.einsum("fi,fi->f", flat_u.reshape(frames, -1), (stiffness @ flat_u.reshape(frames, -1).T).T)
        kinetic = 0.5 * np.einsum("n,fnc->f", layer.mass[skin], v**2)
        energy = elastic + kinetic
        window = FPS / params.soft_hz  # one period, to average the exchange between the two
        early, late = energy[40:40 + int(window)].mean(), energy[-int(window):].mean()
        rates[zeta] = np.log(early / late) / ((frames - window - 40) / FPS)
    assert rates[1e-4] < 0.05  # conserved to a few per cent a second
    expected = 2 * 0.1 * 2 * np.pi * 7.0
    assert rates[0.1] == pytest.approx(expected, rel=0.35)


def test_the_inner_surface_is_attached():
    """Only skin and between-level nodes are free: the skull side never moves, and the
    skin held on bone (rigid weight 1) keeps zero offsets."""
    points, tris, weights = slab(9, 8.0)
    params = flat(layers=2)
    layer = Layer(points, tris, weights, params)
    columns = len(layer.vertices)
    assert layer.free.max() < params.layers * columns  # nothing on the last (skull) level
    assert np.all(weights[layer.vertices[layer.free[layer.free < columns]]] < 1)
    frames = 120
    translate, orient = push(frames)
    result = simulate(held(points, frames), tris, translate, orient, FPS, params, rigid_weights=weights)
    assert np.abs(result.offsets[:, weights < 1]).max() > 0.01
    assert not np.any(result.offsets[:, weights == 1])


def test_expression_inertia_is_a_load(sheet):
    """With a still skull, a held expression rests exactly, but a fast expression change
    jiggles (unlike facedyn.sim.tissue, where the expression is no load)."""
    points, tris, weights = sheet
    frames = 120
    t = np.arange(frames) / FPS
    bulge = np.exp(-np.sum(points[:, :2] ** 2, axis=1) / 8.0)[:, None] * np.array([0.0, 0.0, 1.0])
    fast = np.clip((t - 0.1) / 0.1, 0, 1)
    y = points[None] + (fast**3 * (10 - 15 * fast + 6 * fast**2))[:, None, None] * 0.5 * bulge[None]
    still = np.zeros((frames, 3)), quaternion.identity((frames,))
    moving = simulate(y, tris, *still, FPS, flat(), rigid_weights=weights, neutral=points)
    assert np.abs(moving.dynamics).max() > 1e-3
    held_pose = simulate(held(y[-1], frames), tris, *still, FPS, flat(), rigid_weights=weights, neutral=points)
    assert np.abs(held_pose.offsets).max() < 1e-9


def test_random_actors_are_seeded_and_in_range():
    a, b = VolumetricParams.random(3), VolumetricParams.random(3)
    assert a == b and a != VolumetricParams.random(4)
    draws = [VolumetricParams.random(seed) for seed in range(50)]
    assert all(4.5 <= p.soft_hz <= 8.0 and 1.2 <= p.thickness_cm <= 2.4 and 0.12 <= p.damping_ratio <= 0.35 for p in draws)
    assert np.std([p.soft_hz for p in draws]) > 0.5
    assert VolumetricParams.random(3, layers=2).layers == 2


def test_bad_parameters_and_inputs_are_clear_errors(sheet):
    points, tris, weights = sheet
    with pytest.raises(ValueError, match="soft_hz"):
        VolumetricParams(soft_hz=0.0)
    with pytest.raises(ValueError, match="poisson"):
        VolumetricParams(poisson=0.5)
    with pytest.raises(ValueError, match="layers"):
        VolumetricParams(layers=0)
    with pytest.raises(ValueError, match="skull_translate"):
        simulate(held(points, 5), tris, np.zeros((4, 3)), quaternion.identity((5,)), FPS, rigid_weights=weights)


@pytest.fixture(scope="module")
def face():
    from facedyn.sim.default_face import default_face

    return default_face(resolution=18)  # coarser than the default: the same face, half the points


@pytest.mark.slow  # simulates the volumetric layer for seconds
def test_the_built_in_face_rings_in_the_stated_band(face):
    """On the face the soft regions are held by thinner tissue around them: the ring-down
    peak lies at 1.0-1.3 x soft_hz (about 1.15 x), i.e. 5-9 Hz for VolumetricParams.random's range."""
    frames = 240
    translate, orient = push(frames)
    result = simulate(held(face.neutral, frames), face.topology.triangles(), translate, orient, FPS,
                      VolumetricParams(soft_hz=6.0, damping_ratio=0.05), rigid_weights=face.rigid_weights)
    measured = peak_hz(result.dynamics[36:, face.face_vertices, 1])
    assert 6.0 <= measured <= 1.3 * 6.0, measured


@pytest.mark.slow  # simulates the volumetric layer for seconds
def test_the_two_physics_agree_in_order_of_magnitude_only(face):
    """A 9 Hz platform: both physics give dynamics of the same order, not the same field."""
    from facedyn import motion

    trajectory = motion.platform(9.0, motion.PLATFORM_AMPLITUDE_CM, duration_s=1.0, seed=1)
    y = held(face.neutral, trajectory.frame_count)
    args = (y, face.topology.triangles(), trajectory.translate, trajectory.orient, FPS)
    springs = tissue.simulate(*args, rigid_weights=face.rigid_weights).dynamics[60:, face.face_vertices]
    layer = volumetric.simulate(*args, rigid_weights=face.rigid_weights).dynamics[60:, face.face_vertices]
    rms = [float(np.sqrt(np.mean(np.sum(d**2, axis=-1)))) for d in (springs, layer)]
    assert 1 / 3 < rms[0] / rms[1] < 3, rms
    difference = float(np.sqrt(np.mean(np.sum((springs - layer) ** 2, axis=-1))))
    assert difference > 0.2 * min(rms)  # they are meant to differ


def test_a_step_that_does_not_converge_is_retried_finer_then_an_error_naming_the_frame(sheet, monkeypatch):
    points, tris, weights = sheet
    frames = 4
    translate = np.zeros((frames, 3))
    translate[1:, 1] = 2.0  # a jolt
    monkeypatch.setattr(volumetric, "_MAX_ITERATIONS", 0)  # no step converges, at any step size
    tried = []
    integrate = volumetric._integrate
    monkeypatch.setattr(volumetric, "_integrate", lambda layer, y, skull, fps, params, out: tried.append(params.substeps)
                        or integrate(layer, y, skull, fps, params, out))
    with pytest.raises(tissue.SimulationDiverged, match=r"did not converge at frame \d even at 16 steps per frame"):
        simulate(held(points, frames), tris, translate, quaternion.identity((frames,)), FPS, flat(), rigid_weights=weights)
    assert tried == [1, 2, 4, 8, 16]
