"""The procedural talking face (facedyn.sim.speech) and its takes in the protocol."""
import numpy as np
import pytest

from facedyn.sim.corpus import TakeSpec, expression_weights, protocol, simulate_take
from facedyn.sim.default_face import default_face
from facedyn.sim.speech import BLINK_S, SYLLABLES_PER_S, VISEMES, speech_weights

NAMES = tuple(sorted({name for recipe in VISEMES for name in recipe} | {"eyeBlink_L", "eyeBlink_R", "mouthSmile_L"}))


def test_speech_is_seeded_bounded_and_moves_the_mouth_at_a_syllable_rate():
    fps = 120.0
    weights = speech_weights(NAMES, 1200, fps, seed=3)
    assert weights.shape == (1200, len(NAMES)) and weights.dtype == np.float32
    assert np.array_equal(weights, speech_weights(NAMES, 1200, fps, seed=3))
    assert not np.array_equal(weights, speech_weights(NAMES, 1200, fps, seed=4))
    assert weights.min() >= 0.0 and weights.max() <= 1.0
    jaw = weights[:, NAMES.index("jawOpen")].astype(np.float64)
    assert jaw.std() > 0.05  # the jaw opens and closes
    # syllables: the jaw's motion is concentrated between 1 and 8 Hz (3-6 syllables a second, phrases, pauses)
    spectrum = np.abs(np.fft.rfft(jaw - jaw.mean())) ** 2
    hz = np.fft.rfftfreq(len(jaw), 1 / fps)
    assert spectrum[(hz >= 1.0) & (hz <= 8.0)].sum() > 0.5 * spectrum.sum()
    # smooth like a face, no steps: the fastest change is a full weight over the shortest transition
    # (half of the shortest syllable, 0.6 / the fastest rate) along a smoothstep, whose peak slope is 1.875
    shortest = 0.5 * 0.6 / SYLLABLES_PER_S[1]
    assert np.abs(np.diff(weights, axis=0)).max() * fps < max(1.875 / shortest, np.pi / BLINK_S)
    blinks = weights[:, NAMES.index("eyeBlink_L")]
    assert blinks.max() > 0.9 and np.array_equal(blinks, weights[:, NAMES.index("eyeBlink_R")])


def test_speech_drives_only_the_shapes_a_rig_has():
    assert not speech_weights(("notAShape",), 240, 120.0, seed=0).any()
    assert speech_weights((), 240, 120.0, seed=0).shape == (240, 0)
    with pytest.raises(ValueError, match="fps"):
        speech_weights(NAMES, 10, 0.0, seed=0)


def test_speech_takes_are_performances_of_the_protocol_under_every_motion():
    rig = default_face(resolution=10)
    specs = protocol(rig, "demo")
    speech = [s for s in specs if s.speech]
    held_motions = {s.motion for s in specs if s.expression == "smile"}
    assert {s.motion for s in speech} == held_motions  # one talking take under every protocol motion
    assert all(s.name.startswith("dialog_") and s.dialog is None and s.expression is None for s in speech)  # kept out of the paper's F
    assert len({s.seed for s in speech}) == len(speech) and len({s.name for s in specs}) == len(specs)
    weights = expression_weights(rig, speech[0], 240)
    assert np.array_equal(weights, speech_weights(rig.expression_names, 240, speech[0].fps, speech[0].seed))
    with pytest.raises(ValueError, match="no held expression or dialog"):
        expression_weights(rig, TakeSpec("both", "still", "smile", speech=True), 10)
    # the expression alone never forces the tissue: a talking face on a still head has no dynamics
    still = simulate_take(rig, TakeSpec("talk", "still", speech=True, duration_s=0.5, seed=1))
    assert still.weights.std(axis=0).max() > 0.05
    assert np.abs(still.offsets).max() == 0.0
    assert np.allclose(still.captured, still.quasistatic)
