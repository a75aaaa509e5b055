"""Removals blended per frequency band (facedyn.dynamics.bands): the split, the blend, and the
weights chosen on a session, checked against the session figure they minimize."""
import numpy as np
import pytest

from facedyn.dynamics.bands import BandWeights, BandWeightsFit, lowpass, reach_frames, split
from facedyn.dynamics.diagnostics import SessionScore

FPS = 60.0


def test_the_bands_add_up_to_the_signal_and_the_low_pass_is_the_gaussians():
    """Every band split adds back up to the signal; each low-pass scales a sine by the Gaussian's
    response, half the power at its edge (so neighbouring bands overlap smoothly, with no ripple)."""
    t = np.arange(600) / FPS
    slow, fast = np.sin(2 * np.pi * 1.0 * t), np.sin(2 * np.pi * 12.0 * t)
    signal = np.stack([slow + fast, 2 * slow], axis=1)
    bands = split(signal, (2.0, 4.0, 8.0), FPS)
    assert len(bands) == 4
    np.testing.assert_allclose(sum(bands), signal, atol=1e-12)
    inner = slice(60, -60)  # away from the held ends
    for hz, edge in ((1.0, 2.0), (4.0, 4.0), (12.0, 8.0), (6.0, 2.0)):
        sine = np.sin(2 * np.pi * hz * t)
        gain = 0.5 ** ((hz / edge) ** 2 / 2)
        np.testing.assert_allclose(lowpass(sine, edge, FPS)[inner], gain * sine[inner], atol=2e-3)
    np.testing.assert_allclose(bands[0][inner, 1], 2 * 0.5 ** (1 / 8) * slow[inner], atol=4e-3)


def test_equal_or_single_weights_are_the_mean_or_the_model_and_a_chunk_with_its_reach_is_the_whole():
    rng = np.random.default_rng(3)
    removed = [(rng.normal(size=(200, 5, 3)), rng.normal(size=(200, 5, 3))) for _ in range(2)]
    mean = BandWeights((2.0, 4.0), np.full((3, 2), 0.5)).combine(removed, FPS)
    np.testing.assert_allclose(mean[1], (removed[0][1] + removed[1][1]) / 2, atol=1e-6)
    first = BandWeights((2.0, 4.0), np.array([[1.0, 0.0]] * 3)).combine(removed, FPS)
    np.testing.assert_allclose(first[0], removed[0][0], atol=1e-6)
    weights = BandWeights((2.0, 4.0, 8.0), np.array([[0.2, 0.8], [0.5, 0.5], [1.0, 0.0], [0.7, 0.3]]))
    whole = weights.combine(removed, FPS)
    reach = weights.reach(FPS)
    assert reach == reach_frames(2.0, FPS) > 0 and BandWeights.mean(2).reach(FPS) == 0
    start, stop = 80, 120  # a chunk read with `reach` frames of context gives the whole take's frames
    chunk = weights.combine([(q[start - reach:stop + reach], o[start - reach:stop + reach]) for q, o in removed], FPS)
    np.testing.assert_allclose(chunk[1][reach:-reach], whole[1][start:stop], atol=1e-5)
    assert whole[0].dtype == np.float32


def test_band_weights_are_checked():
    with pytest.raises(ValueError, match="add up to 1"):
        BandWeights((2.0,), np.array([[0.5, 0.6], [1.0, 0.0]]))
    with pytest.raises(ValueError, match="one row per band"):
        BandWeights((2.0, 4.0), np.array([[0.5, 0.5], [1.0, 0.0]]))
    with pytest.raises(ValueError, match="increasing positive"):
        BandWeights((4.0, 2.0), np.full((3, 2), 0.5))
    with pytest.raises(ValueError, match="edges_hz"):
        BandWeights.from_json({"weights": [[1.0]]})
    record = BandWeights((2.0,), np.array([[0.25, 0.75], [1.0, 0.0]])).to_json()
    assert BandWeights.from_json(record).to_json() == record


def _session(rng, takes=5):
    """Takes of a held shape with two noisy removals of their motion, one better slow, one better fast."""
    for k in range(takes):
        frames = 150 + 20 * k
        t = np.arange(frames) / FPS
        slow = np.sin(2 * np.pi * 1.2 * t + k)[:, None, None] * rng.normal(size=(1, 6, 3))
        fast = np.sin(2 * np.pi * 9.0 * t + 2 * k)[:, None, None] * rng.normal(size=(1, 6, 3))
        captured = 1.0 + slow + fast + 0.05 * rng.normal(size=(frames, 6, 3))
        a = 0.5 * slow + fast + 0.1 * rng.normal(size=(frames, 6, 3))  # follows the fast motion
        b = slow + 0.5 * fast + 0.1 * rng.normal(size=(frames, 6, 3))  # follows the slow motion
        orient = np.tile([1.0, 0.0, 0.0, 0.0], (frames, 1)) + 0.02 * rng.normal(size=(frames, 4))
        yield captured, orient / np.linalg.norm(orient, axis=1, keepdims=True), a, b


def test_the_fit_scores_any_weights_as_the_session_figure_would_and_finds_the_least_leaving():
    """The fit's quadratic gives, for any weights, the figure SessionScore computes for the blend so
    weighted; its best weights leave no more than a grid's, than either model or their mean; and
    they follow each model where it is better (a, the fast band; b, the slow one)."""
    rng = np.random.default_rng(7)
    skip, vertices = 6, np.arange(5)
    probe = BandWeights((2.0, 4.0, 8.0), np.array([[0.1, 0.9], [0.4, 0.6], [0.8, 0.2], [0.9, 0.1]]))
    score = SessionScore(vertices, skip, ("a", "b", "mean", "probe"))
    fit = BandWeightsFit((2.0, 4.0, 8.0))
    for captured, orient, a, b in _session(rng):
        blended = probe.combine([(captured - a, a), (captured - b, b)], FPS)[1]
        cleaned, rotations = score.add(captured, orient, {"a": a, "b": b, "mean": (a + b) / 2, "probe": blended})
        fit.add(cleaned, rotations, a[:, vertices].reshape(len(a), -1), b[:, vertices].reshape(len(b), -1), FPS, skip)
    total = score.motion.norm()
    figures = score.motion_left()
    assert fit.left(np.ones(4)) / total == pytest.approx(figures["a"], rel=1e-9)
    assert fit.left(np.zeros(4)) / total == pytest.approx(figures["b"], rel=1e-9)
    assert fit.left(np.full(4, 0.5)) / total == pytest.approx(figures["mean"], rel=1e-9)
    assert fit.left(probe.weights[:, 0]) / total == pytest.approx(figures["probe"], rel=1e-5)  # float32 offsets
    best = fit.best()
    assert np.all((best >= 0) & (best <= 1))
    grid = np.stack(np.meshgrid(*[np.linspace(0, 1, 6)] * 4), axis=-1).reshape(-1, 4)
    assert fit.left(best) <= min(fit.left(w) for w in grid) + 1e-12
    assert fit.left(best) / total < min(figures.values())
    assert best[0] < 0.5 < best[3]
    weights = fit.weights()
    np.testing.assert_allclose(weights.weights.sum(axis=1), 1.0)
    np.testing.assert_allclose(weights.weights[:, 0], best)
