"""Truth-free diagnostics against signals whose answers are known, and against the simulator's truth."""
import numpy as np
import pytest

from facedyn.dynamics import diagnostics
from facedyn.dynamics.samples import default_landmarks
from facedyn.sim.corpus import TakeSpec, simulate_take
from facedyn.sim.default_face import default_face

FPS = 120.0


def sine_points(hz: float, amplitude: float, frames: int = 360, points: int = 5) -> np.ndarray:
    t = np.arange(frames) / FPS
    out = np.zeros((frames, points, 3))
    out[:, :, 1] = amplitude * np.sin(2 * np.pi * hz * t)[:, None]
    return out


def test_peak_frequency_and_band_residual_of_known_sines():
    freqs, power = diagnostics.power_spectrum(sine_points(8.0, 1.0), FPS)
    assert diagnostics.peak_frequency(freqs, power) == pytest.approx(8.0, abs=0.1)
    captured = sine_points(8.0, 1.0) + sine_points(3.0, 0.5)
    left = sine_points(8.0, 0.25) + sine_points(3.0, 0.5)  # a quarter of the 8 Hz motion remains
    everything = np.arange(5)
    assert diagnostics.residual_at_frequency(left, captured, FPS, 8.0, everything) == pytest.approx(0.25, abs=0.02)
    assert diagnostics.residual_at_frequency(captured, captured, FPS, 3.0, everything) == pytest.approx(1.0)


def test_held_expression_spread_measures_distance_from_the_common_shape():
    shape = np.random.default_rng(0).normal(size=(4, 3))
    a = np.repeat(shape[None], 10, 0)
    b = a + np.array([0.0, 0.3, 0.0])  # the same expression, shifted 0.3 in every frame
    spread = diagnostics.held_expression_spread([a, b], np.arange(4))
    assert spread["per_frame_cm"] == pytest.approx(0.15)
    assert spread["across_takes_cm"] == pytest.approx(0.15)
    with pytest.raises(ValueError, match="two takes"):
        diagnostics.held_expression_spread([a], np.arange(4))


def test_resynthesis_residual_is_relative_to_the_removed_dynamics():
    quasistatic = np.zeros((6, 3, 3))
    captured = quasistatic + 1.0
    assert diagnostics.resynthesis_residual(captured, captured, quasistatic, np.arange(3)) == 0.0
    assert diagnostics.resynthesis_residual(captured, quasistatic, quasistatic, np.arange(3)) == pytest.approx(1.0)


def test_on_simulated_truth_the_true_removal_passes_every_diagnostic():
    """A held smile on a 9 Hz platform: the true quasistatic shape keeps almost none of the
    capture's 9 Hz motion, its shape spreads far less than the capture's, and the true
    dynamics ring where the skull drives them, not below 1 Hz."""
    rig = default_face(12)
    takes = [simulate_take(rig, TakeSpec(f"smile_{m}", m, "smile", duration_s=2.0, seed=i)) for i, m in enumerate(("platform:9", "walk"))]
    fv = rig.face_vertices
    platform = takes[0]
    captured = platform.quasistatic + platform.offsets
    spectrum = diagnostics.offset_spectrum(platform.offsets, platform.skull_translate, platform.skull_orient,
                                           default_landmarks(rig.neutral), FPS, fv)
    assert spectrum["skull_peak_hz"] == pytest.approx(9.0, abs=0.3)
    assert spectrum["offsets_peak_hz"] == pytest.approx(9.0, abs=0.5)
    assert spectrum["offsets_below_1hz_fraction"] < 0.05
    assert diagnostics.residual_at_frequency(platform.quasistatic, captured, FPS, 9.0, fv) < 0.05
    skip = int(0.5 * FPS)
    after = diagnostics.held_expression_spread([t.quasistatic for t in takes], fv, skip)
    before = diagnostics.held_expression_spread([t.quasistatic + t.offsets for t in takes], fv, skip)
    assert after["per_frame_cm"] < 0.3 * before["per_frame_cm"]


def test_the_streamed_sag_norm_is_the_least_squares_residual_of_all_takes_at_once():
    """BeyondSag adds takes one at a time; its norm is that of the residual of one least-squares
    fit of the centred values on the centred rotation entries over every take, as written out."""
    from facedyn.dynamics.diagnostics import BeyondSag, motion_left_beyond_sag

    rng = np.random.default_rng(3)
    values = [rng.normal(size=(n, 12)) + rng.normal(size=12) for n in (40, 55, 31)]
    rotations = [rng.normal(size=(len(v), 9)) * 1e-2 + np.eye(3).ravel() for v in values]
    sag = rng.normal(size=(9, 12))
    values = [v + (r - r.mean(0)) @ sag for v, r in zip(values, rotations)]
    centred = np.concatenate([v - v.mean(0) for v in values])
    rotation = np.concatenate([r - r.mean(0) for r in rotations])
    coef, *_ = np.linalg.lstsq(rotation, centred, rcond=None)
    streamed = BeyondSag()
    for v, r in zip(values, rotations):
        streamed.add(v, r)
    assert streamed.norm() == pytest.approx(np.linalg.norm(centred - rotation @ coef), rel=1e-9)
    left = [0.3 * v for v in values]
    assert motion_left_beyond_sag(left, values, rotations) == pytest.approx(0.3, rel=1e-9)


def test_a_session_score_ranks_removals_in_one_pass_as_each_alone_would():
    """Several removals scored together give each the figure it gets alone, and what a removal
    leaves is the capture with its tracker spikes replaced, less its offsets: the true offsets
    leave only the noise, none leave everything."""
    from facedyn.dynamics.diagnostics import SessionScore

    rng = np.random.default_rng(5)
    frames, points = 120, 30
    vertices, skip = np.arange(20), 10
    takes = []
    for k in range(3):
        held = rng.normal(size=(points, 3))
        angle = 0.02 * np.sin(np.arange(frames) * (0.3 + 0.1 * k))
        orient = np.stack([np.cos(angle / 2), np.sin(angle / 2), 0 * angle, 0 * angle], axis=1)
        offsets = 0.05 * np.sin(np.arange(frames)[:, None, None] * 0.7 + rng.normal(size=(1, points, 3)))
        noise = 1e-4 * rng.normal(size=(frames, points, 3))
        takes.append((held + offsets + noise, orient, offsets))
    together = SessionScore(vertices, skip, ("truth", "none", "half"))
    alone = {name: SessionScore(vertices, skip, (name,)) for name in ("truth", "none", "half")}
    for captured, orient, offsets in takes:
        removals = {"truth": offsets, "none": 0 * offsets, "half": 0.5 * offsets}
        together.add(captured, orient, removals)
        for name, score in alone.items():
            score.add(captured, orient, {name: removals[name]})
    figures = together.motion_left()
    assert figures == {name: score.motion_left()[name] for name, score in alone.items()}
    assert figures["none"] == pytest.approx(1.0) and figures["truth"] < 0.01
    assert figures["half"] == pytest.approx(0.5, abs=0.01)
    with pytest.raises(ValueError, match="removals"):
        together.add(*takes[0][:2], {"truth": takes[0][2]})
