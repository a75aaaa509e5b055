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
