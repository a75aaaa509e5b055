"""A procedural performance: speech-like expression changes over a rig's blend shapes.

Live Link performances need ../shared/data; without them a corpus holds only held
expressions, and a network that never saw the face change its expression while the head
moves takes any expression change for dynamics. This source gives a data-free corpus
performances to learn from. It follows general figures of talking faces, not any capture
(the test takes' in particular): syllables at 3-6 per second, each a mouth shape (a
viseme: open, rounded, spread, closed...) with the jaw opening on its nucleus, pauses of
0.2-0.7 s between phrases of 1-3 s, a slower emotional layer (smile or frown, brows) that
changes every 1-3 s, and blinks every 2-6 s. Key poses are joined by C2 smoothstep
transitions (facedyn.motion's fades), so the weights have continuous accelerations like real curves.

Only the shapes a rig has are driven (ARKit names, as ICT-FaceKit and the built-in face
use); a rig with none of them gets the neutral. Everything is drawn from the seed.
"""
from __future__ import annotations

import numpy as np

from facedyn.motion import _fade

# Mouth shapes of syllable nuclei, as shape-weight recipes (scaled per syllable).
VISEMES: tuple[dict[str, float], ...] = (
    {"jawOpen": 0.7},  # "ah"
    {"jawOpen": 0.35, "mouthStretch_L": 0.5, "mouthStretch_R": 0.5},  # "eh"
    {"jawOpen": 0.15, "mouthSmile_L": 0.4, "mouthSmile_R": 0.4, "mouthStretch_L": 0.4, "mouthStretch_R": 0.4},  # "ee"
    {"jawOpen": 0.3, "mouthFunnel": 0.7},  # "oh"
    {"jawOpen": 0.1, "mouthPucker": 0.8},  # "oo", "w"
    {"mouthUpperUp_L": 0.4, "mouthUpperUp_R": 0.4, "jawOpen": 0.1},  # "f", "v"
    {"jawOpen": 0.05},  # "m", "b", "p": lips closed
    {"jawOpen": 0.25, "mouthFrown_L": 0.2, "mouthFrown_R": 0.2},  # "uh"
)
# Slow layer: what the face shows while it talks (scaled per segment).
MOODS: tuple[dict[str, float], ...] = (
    {},
    {"mouthSmile_L": 0.5, "mouthSmile_R": 0.5, "eyeSquint_L": 0.3, "eyeSquint_R": 0.3},
    {"mouthFrown_L": 0.4, "mouthFrown_R": 0.4, "browDown_L": 0.4, "browDown_R": 0.4},
    {"browInnerUp_L": 0.6, "browInnerUp_R": 0.6, "browOuterUp_L": 0.4, "browOuterUp_R": 0.4},
    {"mouthSmile_L": 0.6, "eyeSquint_L": 0.2, "jawLeft": 0.3},
    {"mouthSmile_R": 0.6, "eyeSquint_R": 0.2, "jawRight": 0.3},
    {"noseSneer_L": 0.4, "noseSneer_R": 0.4, "browDown_L": 0.3, "browDown_R": 0.3},
)
SYLLABLES_PER_S = (3.0, 6.0)
PHRASE_S = (1.0, 3.0)
PAUSE_S = (0.2, 0.7)
MOOD_S = (1.0, 3.0)
BLINK_EVERY_S = (2.0, 6.0)
BLINK_S = 0.15


def speech_weights(names, frame_count: int, fps: float, seed: int) -> np.ndarray:
    """(frame_count, len(names)) weights in [0, 1] of a talking face, drawn from `seed`."""
    if frame_count < 0 or not fps > 0:
        raise ValueError(f"speech needs a non-negative frame count and a positive fps, got {frame_count}, {fps}")
    rng = np.random.default_rng([int(seed), 0x737063])  # "spc": a stream of its own
    times = np.arange(frame_count) / fps
    duration = frame_count / fps
    index = {name: i for i, name in enumerate(names)}
    weights = np.zeros((frame_count, len(index)))
    _add(weights, index, _keyed(times, _syllables(rng, duration), VISEMES))
    _add(weights, index, _keyed(times, _moods(rng, duration), MOODS))
    blinks = _blinks(rng, times, duration)
    for name in ("eyeBlink_L", "eyeBlink_R"):
        if name in index:
            weights[:, index[name]] += blinks
    return np.clip(weights, 0.0, 1.0).astype(np.float32)


def _syllables(rng: np.random.Generator, duration: float) -> list[tuple[float, float, int, float]]:
    """(start, transition, viseme, intensity) keys: phrases of syllables, rest between phrases."""
    rate = rng.uniform(*SYLLABLES_PER_S)
    keys, t = [], rng.uniform(0.0, 0.3)
    while t < duration:
        phrase_end = t + rng.uniform(*PHRASE_S)
        while t < min(phrase_end, duration):
            step = rng.uniform(0.6, 1.4) / rate
            keys.append((t, 0.5 * step, int(rng.integers(len(VISEMES))), rng.uniform(0.4, 1.0)))
            t += step
        pause = rng.uniform(*PAUSE_S)
        keys.append((t, min(pause, 0.2), -1, 0.0))  # the mouth relaxes to rest
        t += pause
    return keys


def _moods(rng: np.random.Generator, duration: float) -> list[tuple[float, float, int, float]]:
    keys, t = [], 0.0
    while t < duration:
        length = rng.uniform(*MOOD_S)
        keys.append((t, min(0.4, 0.5 * length), int(rng.integers(len(MOODS))), rng.uniform(0.3, 1.0)))
        t += length
    return keys


def _keyed(times: np.ndarray, keys, recipes) -> dict[str, np.ndarray]:
    """Per shape, the weight curve that moves from key pose to key pose (-1: rest)."""
    curves: dict[str, np.ndarray] = {name: np.zeros_like(times) for recipe in recipes for name in recipe}
    previous = {name: 0.0 for name in curves}
    for start, transition, which, intensity in keys:
        target = {name: 0.0 for name in curves}
        if which >= 0:
            target.update({name: value * intensity for name, value in recipes[which].items()})
        profile = _fade(times - start, transition)
        for name, curve in curves.items():
            curve += (target[name] - previous[name]) * profile
        previous = target
    return curves


def _blinks(rng: np.random.Generator, times: np.ndarray, duration: float) -> np.ndarray:
    blink = np.zeros_like(times)
    t = rng.uniform(*BLINK_EVERY_S) * rng.uniform(0.0, 1.0)
    while t < duration:
        phase = (times - t) / BLINK_S
        blink = np.maximum(blink, np.where((phase > 0) & (phase < 1), np.sin(np.pi * np.clip(phase, 0, 1)) ** 2, 0.0))
        t += rng.uniform(*BLINK_EVERY_S)
    return blink


def _add(weights: np.ndarray, index: dict[str, int], curves: dict[str, np.ndarray]) -> None:
    for name, curve in curves.items():
        if name in index:
            weights[:, index[name]] += curve

