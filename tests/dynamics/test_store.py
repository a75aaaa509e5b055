"""The on-disk training store: what goes in comes back, statistics streamed exactly, and
training streamed in chunks matches training on the whole set in memory."""
import gc
import weakref

import numpy as np
import pytest
import torch
from synthetic_face import curved_sheet, jiggle, platform_motion, top_rows

from facedyn.dynamics import training
from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.features import compute_features
from facedyn.dynamics.skull import to_world
from facedyn.dynamics.store import BLOCK_FRAMES, WINDOW_INDEX, Moments, StreamedExamples, TrainingStore, moments_of
from facedyn.dynamics.training import PairSet, TrainConfig, train_removal
from facedyn.dynamics.training_sequence import TrainingSequence

FPS = 120.0


@pytest.fixture(scope="module")
def corpus():
    pts, topo = curved_sheet(12, 10)
    pts[:, 1] *= 0.5
    face = FaceSetup.build(topo, pts, rigid_vertices=top_rows(12, 10, 2), sample_count=24)
    gain = np.clip((pts[:, 1].max() - pts[:, 1]) / np.ptp(pts[:, 1]), 0, 1) ** 1.5
    takes = []
    for i, hz in enumerate((5.0, 6.5, 8.0, FPS / 21.0)):
        t, q = platform_motion(240, FPS, hz, seed=i)
        offsets = gain[None, :, None] * jiggle(t, q, FPS)[:, None, :]
        takes.append(TrainingSequence(f"platform_{i}", to_world(pts[None] + offsets, t, q).astype(np.float32), FPS, t, q, "world"))
    return face, takes


def test_store_reads_back_what_was_appended_and_streams_exact_moments(tmp_path):
    rng = np.random.default_rng(0)
    a = rng.normal(3.0, 2.0, (70, 4, 5)).astype(np.float32)
    b = rng.normal(-1.0, 0.5, (45, 4, 5)).astype(np.float32)
    with TrainingStore({"x": (4, 5), "y": (2,)}, scratch=tmp_path) as store:
        store.append("a", {"x": a[:30], "y": np.zeros((30, 2))})
        store.append("a", {"x": a[30:], "y": np.ones((40, 2))})  # a take in two chunks
        store.append("b", {"x": b, "y": np.full((45, 2), 2.0)})
        store.finish()
        assert [(t.name, t.start, t.stop) for t in store.takes] == [("a", 0, 70), ("b", 70, 115)]
        rows = np.array([0, 1, 2, 40, 69, 70, 71, 114])
        np.testing.assert_array_equal(store.read("x", rows), np.concatenate([a, b])[rows])
        np.testing.assert_array_equal(store.rows_of(["b"]), np.arange(70, 115))
        both = np.concatenate([a, b]).reshape(-1, 5).astype(np.float64)
        m = store.moments("x", ["a", "b"])
        assert m.count == len(both)
        np.testing.assert_allclose(m.mean, both.mean(axis=0), rtol=1e-12)
        np.testing.assert_allclose(np.sqrt(m.variance), both.std(axis=0), rtol=1e-10)
        np.testing.assert_allclose(store.moments("y", ["a"]).mean, [4 / 7, 4 / 7])
        with pytest.raises(ValueError, match="unique"):
            store.append("a", {"x": a[:1], "y": np.zeros((1, 2))})
        with pytest.raises(ValueError, match="store's"):
            store.append("c", {"x": a[:1, :3], "y": np.zeros((1, 2))})
        folder = store.folder
    assert not folder.exists()
    merged = Moments.of(both[:7]).merge(moments_of(both[7:]))
    np.testing.assert_allclose(merged.m2, ((both - both.mean(axis=0)) ** 2).sum(axis=0), rtol=1e-10)


def test_chunks_hand_out_every_example_once_in_a_seeded_order(tmp_path):
    rows = 300
    with TrainingStore({"v": (1,)}, scratch=tmp_path) as store:
        store.append("t", {"v": np.arange(rows, dtype=np.float32)[:, None]})
        store.finish()
        streamed = StreamedExamples(store, np.arange(10, rows), 1, lambda a: a["v"][:, 0], resident_bytes=4 * 2 * BLOCK_FRAMES)
        assert not streamed.resident and streamed.chunk_rows == 2 * BLOCK_FRAMES

        def order(seed):
            return [c.tolist() for c in streamed.chunks(torch.Generator().manual_seed(seed))]

        chunks = order(1)
        assert all(len(c) <= 2 * BLOCK_FRAMES for c in chunks)
        assert sorted(v for c in chunks for v in c) == list(range(10, rows))
        assert order(1) == chunks and order(2) != chunks
        whole = StreamedExamples(store, np.arange(10, rows), 1, lambda a: a["v"][:, 0], resident_bytes=1 << 20)
        assert whole.resident and [c.tolist() for c in whole.chunks(torch.Generator())] == [list(range(10, rows))]


@pytest.mark.parametrize("resident", [1 << 30, 60_000])
def test_gathered_pairs_equal_the_whole_take_features(corpus, monkeypatch, tmp_path, resident):
    """Takes prepared in chunks of frames, stored as per-frame velocities and gathered back
    as pairs, in memory or in chunks, give exactly the paper's features of each whole take,
    and the store's moments are those of the features."""
    face, takes = corpus
    monkeypatch.setattr(training, "PREPARE_FRAMES", 50)
    config = TrainConfig(sample_positions=True, resident_bytes=resident)
    positions = training.sample_positions(face)
    names = [t.name for t in takes[:2]]
    store, _, _ = training.store_takes(takes[:2], lambda take: training._prepare(take, face, config), tmp_path, {"skin": config.window})
    with store:
        examples = StreamedExamples(store, store.rows_of(names), len(face.samples),
                                    lambda a: PairSet(a["skull"], a["skin"], a[WINDOW_INDEX % "skin"], a["targets"], a["positions"],
                                                      torch.device("cpu")), resident)
        assert examples.resident == (resident > 1e6)
        got = np.concatenate([chunk.gather(torch.arange(len(chunk)))[0].numpy() for chunk in examples.chunks()])
        moments = store.moments("skin", names)
    expected = []
    for take in takes[:2]:
        whole = compute_features(take.points[:, face.samples], take.translate, take.orient, face.landmarks, FPS, space="world", backend="numpy")
        keep = slice(config.trim, len(take.points) - config.trim)
        skull, skin = whole.skull[keep], whole.skin[keep]
        pairs = np.concatenate([np.repeat(skull[:, None], skin.shape[1], 1), skin, np.broadcast_to(positions, skin.shape[:2] + (3,))], -1)
        expected.append(pairs.reshape(-1, pairs.shape[-1]))
    expected = np.concatenate(expected)
    np.testing.assert_allclose(got, expected, atol=1e-3)
    skin = expected[:, skull.shape[1]: -3].astype(np.float64)
    assert moments.count == len(skin)
    np.testing.assert_allclose(moments.mean, skin.mean(axis=0), atol=1e-6)
    np.testing.assert_allclose(np.sqrt(moments.variance), skin.std(axis=0), rtol=1e-4, atol=1e-6)


def test_training_batches_draw_each_pair_once_and_split_equals_concatenated():
    """A full epoch's batches hold every (frame, sample) pair exactly once, and the split
    first layer predicts what the concatenated inputs predict."""
    rng = np.random.default_rng(4)
    frames, samples, w = 40, 37, 2
    velocities = rng.normal(size=(frames + 1, samples, 3)).astype(np.float32)
    window = np.clip(np.arange(frames)[:, None] + np.arange(-w, w + 1)[None, :], 0, frames)
    pairs = PairSet(rng.normal(size=(frames, 5)).astype(np.float32), velocities, window, rng.normal(size=(frames, samples, 3)).astype(np.float32),
                    rng.normal(size=(frames, samples, 3)).astype(np.float32), torch.device("cpu"))
    seen = []
    network = training.Network(training.removal_spec(5, (2 * w + 1) * 3 + 3))
    for (skull, skin, rows), targets in pairs.batches(1.0, 100, torch.Generator().manual_seed(0), torch.device("cpu")):
        assert len(skin) == len(targets) <= 100 and len(skull) < len(skin)
        joined = torch.cat([skull[rows], skin], dim=1)
        torch.testing.assert_close(network.normalized_split(skull, skin, rows), network.normalized(joined), rtol=1e-5, atol=1e-6)
        seen.extend(map(tuple, joined.numpy().round(5).tolist()))
    everything = pairs.gather(torch.arange(len(pairs)))[0].numpy().round(5)
    assert sorted(seen) == sorted(map(tuple, everything.tolist()))
    half = sum(len(t) for _, t in pairs.batches(0.5, 100, torch.Generator().manual_seed(0), torch.device("cpu")))
    assert half == frames * round(0.5 * samples)


@pytest.mark.slow  # trains F for 20 epochs twice, then 2 epochs twice
def test_streamed_training_matches_training_in_memory(corpus, tmp_path):
    """One resident chunk is the in-memory trainer; chunks of 1 MB shuffle by blocks and
    land within a few percent of it, with identical normalization."""
    face, takes = corpus
    models = {}
    for label, resident in (("memory", 1 << 30), ("streamed", 1 << 20)):
        config = TrainConfig(epochs=20, batch_size=1000, validation=("platform_3",), seed=0, resident_bytes=resident)
        models[label] = train_removal(takes, face, config, scratch=tmp_path)
    memory, streamed = models["memory"], models["streamed"]
    for name in ("input_mean", "input_std", "output_mean", "output_scale"):
        torch.testing.assert_close(getattr(memory.network, name), getattr(streamed.network, name))
    assert memory.info["training"]["train_pairs"] == streamed.info["training"]["train_pairs"] == 3 * 220 * 24
    a, b = memory.info["validation"], streamed.info["validation"]
    assert a["zero_offset_rms_cm"] == pytest.approx(b["zero_offset_rms_cm"], rel=1e-6)
    assert a["rms_cm"] < 0.1 * a["zero_offset_rms_cm"] and b["rms_cm"] < 0.1 * b["zero_offset_rms_cm"], (a, b)
    assert b["rms_cm"] == pytest.approx(a["rms_cm"], rel=0.15)  # measured: 3% apart
    assert list(tmp_path.iterdir()) == []  # the stores are gone
    # streamed training is seeded too: two epochs already cover the initial weights and each epoch's block shuffle
    once, again = (train_removal(takes, face, TrainConfig(epochs=2, batch_size=1000, validation=("platform_3",), seed=0, resident_bytes=1 << 20))
                   for _ in range(2))
    for p, q in zip(once.network.parameters(), again.network.parameters()):
        torch.testing.assert_close(p, q, rtol=0, atol=0)


def test_a_take_generator_is_read_one_take_at_a_time(corpus):
    """Training from a generator holds one take at a time: each is dropped before the next is read."""
    face, takes = corpus
    alive = []

    def lazily():
        for take in takes:
            gc.collect()
            assert all(ref() is None for ref in alive), "an earlier take is still held"
            copy = TrainingSequence(take.name, take.points.copy(), take.fps, take.translate, take.orient, take.space)
            alive.append(weakref.ref(copy.points))
            yield copy
            del copy

    model = train_removal(lazily(), face, TrainConfig(epochs=1, batch_size=1000))
    assert [t["name"] for t in model.info["training"]["takes"]] == [t.name for t in takes]


def test_pairset_gathers_frame_and_sample_inputs():
    rng = np.random.default_rng(3)
    skull, targets = rng.normal(size=(5, 2)).astype(np.float32), rng.normal(size=(5, 3, 3)).astype(np.float32)
    velocities = rng.normal(size=(7, 3, 3)).astype(np.float32)
    window = np.array([[6, 0, 1], [0, 1, 2], [1, 2, 3], [2, 3, 4], [3, 4, 6]])  # 6: beyond the take (zero)
    velocities[6] = 0
    positions = rng.normal(size=(5, 3, 3)).astype(np.float32)
    pairs = PairSet(skull, velocities, window, targets, positions, torch.device("cpu"))
    x, y = pairs.gather(torch.tensor([0, 4, 14]))
    f, s = np.array([0, 1, 4]), np.array([0, 1, 2])
    skin = velocities[window[f], s[:, None]].reshape(3, -1)
    np.testing.assert_array_equal(x.numpy(), np.concatenate([skull[f], skin, positions[f, s]], axis=1))
    np.testing.assert_array_equal(y.numpy(), targets[f, s])


def test_a_time_limit_stops_training_before_an_epoch_that_would_overrun_it(corpus):
    """A limit already spent gives one epoch (there is always one); a far one, every epoch;
    the one epoch is the first epoch of the unlimited training (the limit only cuts it short)."""
    import time

    face, takes = corpus
    config = TrainConfig(epochs=3, batch_size=1000, validation=("platform_3",), seed=0)
    whole = train_removal(takes, face, config)
    cut = train_removal(takes, face, TrainConfig(**{**config.__dict__, "time_limit_s": 1e-3}), started=time.monotonic() - 1.0)
    far = train_removal(takes, face, TrainConfig(**{**config.__dict__, "time_limit_s": 1e6}))
    assert len(cut.info["loss_curve"]) == 1 and len(far.info["loss_curve"]) == len(whole.info["loss_curve"]) == 3
    assert cut.info["loss_curve"][0] == whole.info["loss_curve"][0]
    with pytest.raises(ValueError, match="time_limit_s"):
        TrainConfig(time_limit_s=0.0)
