"""Long takes: processors stream in chunks, long layers are value clips, interrupted writes leave nothing behind."""
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from pxr import Usd

from facedyn.cli import main
from facedyn.sim.corpus import TakeSpec
from facedyn.sim.default_face import default_face
from facedyn.stabilize.api import stabilize
from facedyn.usd import clips, layers
from facedyn.processors.corpus_writer import build_corpus
from facedyn.usd.take import read_take


def cli(*argv):
    return main([str(a) for a in argv] + ["-q"])


@pytest.fixture(scope="module")
def take(tmp_path_factory):
    folder = tmp_path_factory.mktemp("long")
    build_corpus(folder, default_face(12), [TakeSpec("walk", "walk", "smile", duration_s=3.0, seed=3)])
    return folder / "walk"


@pytest.mark.slow  # stabilizes, trains on or writes a 3 s take several ways
def test_streamed_stabilize_equals_the_in_memory_chunked_solve(take, tmp_path):
    out = tmp_path / "stabilized.usdc"
    assert cli("stabilize", take / "take.usda", "-o", out, "--chunk-frames", "128", "--chunk-overlap", "16") == 0
    capture, _ = read_take(take / "capture.usdc")
    expected = stabilize(capture.world_points(), capture.fps, rest=capture.rest_points,
                         weights=capture.rigid_weights.astype(np.float64), chunk_frames=128, chunk_overlap=16)
    solved = Usd.Stage.Open(str(out))
    assert not Usd.ClipsAPI(solved.GetPrimAtPath("/Performance/Skull")).GetClips()  # short: one layer
    from facedyn.usd.take import read_layers

    perf = read_layers([out, take / "capture.usdc"])  # composed at the capture's rate
    assert perf.frame_count == capture.frame_count > 2 * 128
    translate, orient = perf.skull()
    np.testing.assert_allclose(translate, expected.translate, atol=1e-5)
    np.testing.assert_allclose(np.abs(np.sum(orient * expected.orient, axis=1)), 1.0, atol=1e-9)
    np.testing.assert_allclose(perf.points, expected.skull_points, atol=1e-4)
    np.testing.assert_allclose(perf.solve_error, expected.solve_error, atol=1e-5)


@pytest.mark.slow  # stabilizes, trains on or writes a 3 s take several ways
def test_a_long_layer_is_written_as_value_clips_that_compose_like_one_layer(take, tmp_path, monkeypatch):
    one = tmp_path / "one" / "stabilized.usdc"
    clipped = tmp_path / "clipped" / "stabilized.usdc"
    root = take / "take.usda"
    assert cli("stabilize", root, "-o", one, "--chunk-frames", "128", "--chunk-overlap", "16") == 0
    monkeypatch.setattr(clips, "CLIP_THRESHOLD", 100)
    assert cli("stabilize", root, "-o", clipped, "--chunk-frames", "128", "--chunk-overlap", "16") == 0
    folders = list(clipped.parent.glob("stabilized.*.clips"))
    assert len(folders) == 1 and len(list(folders[0].glob("stabilized.*.usdc"))) >= 3
    assert (folders[0] / "manifest.usda").is_file()
    stage = Usd.Stage.Open(str(clipped))
    assert list(Usd.ClipsAPI(stage.GetPrimAtPath("/Performance/Skull")).GetClips()) == [clips.clip_set_name(clipped)]
    whole = [read_take_over(path, take) for path in (one, clipped)]
    np.testing.assert_array_equal(whole[0].points, whole[1].points)
    np.testing.assert_array_equal(whole[0].skull_translate, whole[1].skull_translate)
    np.testing.assert_array_equal(whole[0].frames, whole[1].frames)
    # attached to the root, the clipped layer is what every reader and validate see
    assert cli("stabilize", root, "-o", take / "stabilized.usdc", "--attach", root, "--chunk-frames", "128", "--chunk-overlap", "16") == 0
    stabilized, _ = read_take(root)
    np.testing.assert_array_equal(stabilized.points, whole[0].points)
    assert main(["validate", str(root)]) == 0
    assert main(["inspect", str(root)]) == 0
    # a re-run with other parameters replaces the clips of the earlier run
    assert cli("stabilize", root, "-o", clipped, "--chunk-frames", "256", "--chunk-overlap", "16") == 0
    assert len(list(clipped.parent.glob("stabilized.*.clips"))) == 1
    monkeypatch.setattr(clips, "CLIP_THRESHOLD", 100_000)  # short again: one layer, no clips left behind
    assert cli("stabilize", root, "-o", clipped) == 0
    assert not list(clipped.parent.glob("*.clips"))


def read_take_over(layer, take):
    from facedyn.usd.take import read_layers

    return read_layers([layer, take / "capture.usdc"])  # composed at the capture's rate


WRITER = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    import numpy as np
    from facedyn.processors.commandline import signals_raise
    from facedyn.usd import layers, schema
    from facedyn.usd.timing import Timing

    out = Path(sys.argv[1])
    frames = np.arange(1001, 1001 + 300, dtype=float)
    content = layers.LayerContent(frames=frames, face=schema.FaceAttributes(role="stabilized"))
    def chunks():
        for a in range(0, 300, 100):
            yield layers.LayerContent(frames=frames[a:a + 100], points=np.zeros((100, 50, 3), np.float32))
            print("chunk", flush=True)
            time.sleep(60)
    provenance = schema.Provenance(processor="stabilize", version="test", parameters={}, frame_range=(1001, 1300),
                                   inputs=[], role="stabilized")
    with signals_raise():
        layers.write_layer(out, content, Timing(120.0, 120.0, 1001.0, 1300.0), provenance, chunks=chunks(), clip_threshold=int(sys.argv[2]))
""")


@pytest.mark.parametrize("threshold", [100, 1000], ids=["clipped", "one-layer"])
def test_sigterm_mid_write_leaves_no_temporary_files(tmp_path, threshold):
    out = tmp_path / "stabilized.usdc"
    writer = subprocess.Popen([sys.executable, "-c", WRITER, str(out), str(threshold)], stdout=subprocess.PIPE, text=True)
    assert writer.stdout.readline().strip() == "chunk"  # the first chunk is in (its clip written, for the clipped case)
    if threshold == 100:
        assert any(p.name.startswith(".stabilized.") for p in tmp_path.iterdir())  # the clips' staging folder exists
    writer.send_signal(signal.SIGTERM)
    assert writer.wait(timeout=60) != 0
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_write_sweeps_temporaries_of_dead_writers_only(tmp_path):
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    try:
        out = tmp_path / "stabilized.usdc"
        stale = tmp_path / f".stabilized.{dead.pid}.ab12cd.usdc"
        stale_clips = tmp_path / f".stabilized.0123abcd.clips.{dead.pid}.tmp"
        other = tmp_path / f".stabilized.{live.pid}.ef34gh.usdc"
        unrelated = tmp_path / ".notes.txt"
        for path in (stale, other, unrelated):
            path.write_bytes(b"x")
        stale_clips.mkdir()
        assert sorted(layers.sweep_stale_temps(out)) == sorted([stale, stale_clips])
        assert other.exists() and unrelated.exists() and not stale.exists() and not stale_clips.exists()
    finally:
        live.kill()
        live.wait()


@pytest.mark.slow  # stabilizes, trains on or writes a 3 s take several ways
def test_streamed_remove_and_synthesize_equal_the_whole_take(take, tmp_path, monkeypatch):
    from facedyn.dynamics.modelfile import load_model
    from facedyn.dynamics.removal import remove_dynamics
    from facedyn.dynamics.synthesis import synthesize_dynamics
    from facedyn.processors import model_steps

    corpus = take.parent
    models = tmp_path / "models"
    root = take / "take.usda"
    assert main(["train-removal", str(corpus), "-o", str(models / "f.removal"), "--skull", "truth", "--epochs", "1",
                 "--samples", "32", "--json"]) == 0
    assert main(["train-synthesis", str(corpus), "-o", str(models / "h.synthesis"), "--quasistatic", str(models / "f.removal"),
                 "--skull", "truth", "--epochs", "1", "--json"]) == 0
    assert cli("stabilize", root, "-o", take / "stabilized.usdc", "--attach", root) == 0
    monkeypatch.setattr(model_steps, "CHUNK_FRAMES", 100)  # 360 frames: four chunks, each with context on both sides
    stabilized, _ = read_take(root)
    assert cli("remove", root, "-o", take / "quasistatic.usdc", "--model", models / "f.removal", "--attach", root) == 0
    quasistatic, _ = read_take(root)
    expected, offsets = remove_dynamics(stabilized.points, *stabilized.skull(), stabilized.fps, load_model(models / "f.removal"))
    assert np.abs(offsets).max() > 1e-4  # the model predicts something
    np.testing.assert_allclose(quasistatic.points, expected, atol=2e-6)
    np.testing.assert_allclose(quasistatic.offsets, offsets, atol=2e-6)
    assert cli("synthesize", root, "-o", take / "synthesized.hop.usdc", "--model", models / "h.synthesis", "--skull-motion", "hop",
               "--attach", root) == 0
    synthesized, _ = read_take(root)
    expected, offsets = synthesize_dynamics(quasistatic.points, *synthesized.skull(), quasistatic.fps, load_model(models / "h.synthesis"))
    np.testing.assert_allclose(synthesized.points, expected, atol=2e-6)
    np.testing.assert_allclose(synthesized.offsets, offsets, atol=2e-6)


@pytest.mark.slow  # stabilizes, trains on or writes a 3 s take several ways
@pytest.mark.parametrize("mask, rest", [("all", "estimate"), ("rigid", "estimate")], ids=["plain-capture", "estimated-rest"])
def test_a_long_take_is_solved_against_one_rest_and_mask_found_on_a_frame_sample(take, tmp_path, mask, rest):
    from facedyn.stabilize.schedule import Schedule

    out = tmp_path / "stabilized.usdc"
    assert cli("stabilize", take / "take.usda", "-o", out, "--chunk-frames", "128", "--chunk-overlap", "16",
               "--mask", mask, "--rest", rest) == 0
    capture, _ = read_take(take / "capture.usdc")
    weights = capture.rigid_weights.astype(np.float64) if mask == "rigid" else None
    schedule = Schedule.locked() if weights is None else Schedule()
    expected = stabilize(capture.world_points(), capture.fps, weights=weights, schedule=schedule, chunk_frames=128, chunk_overlap=16)
    solved = read_take_over(out, take)
    np.testing.assert_allclose(schema_rest(out), expected.rest, atol=1e-5)  # the same rest (and mask) as the whole take's
    # In memory, an estimated rest is found after the initial alignment (to the first frame); streamed, the chunks
    # start aligned to it. The fixed-iteration solves end within the 0.001 cm of each other.
    np.testing.assert_allclose(solved.skull_translate, expected.translate, atol=1e-3)
    np.testing.assert_allclose(solved.points, expected.skull_points, atol=1e-3)


def schema_rest(layer):
    from facedyn.usd import schema

    stage = Usd.Stage.Open(str(layer))
    return schema.FaceAttributes.read(stage.GetPrimAtPath("/Performance/Skull/Face")).rest_points
