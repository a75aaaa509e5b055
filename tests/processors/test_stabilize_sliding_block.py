"""A plain capture whose largest still region is a sliding block: `stabilize` finds the bone under it, in memory and
streamed in chunks (facedyn.stabilize.rigidity.discover_rigid_mode)."""
import dataclasses
import json

import numpy as np
import pytest

from facedyn.cli import main
from facedyn.evaluation import stabilization_errors
from facedyn.sim.corpus import TakeSpec, simulate_take
from facedyn.sim.default_face import default_face
from facedyn.stabilize.rigidity import estimate_rigidity
from facedyn.processors.corpus_writer import build_corpus
from facedyn.usd.take import read_layers, read_take

SPEC = TakeSpec("talk_walk", "walk", speech=True, duration_s=3.0, seed=5)


@pytest.fixture(scope="module")
def small_bone():
    """The built-in face with bone under its top quarter only (as on the ICT rig, 8 % of whose mesh is bone): the
    brow and cheek tissue beside the bone hangs on soft springs and slides as one block."""
    rig = default_face(12)
    bone = rig.rigid_weights == 1
    kept = bone & (rig.neutral[:, 1] >= np.percentile(rig.neutral[bone, 1], 75))
    return dataclasses.replace(rig, rigid_weights=kept.astype(np.float32))


@pytest.fixture(scope="module")
def take(small_bone, tmp_path_factory):
    folder = tmp_path_factory.mktemp("sliding")
    build_corpus(folder, small_bone, [SPEC])
    return folder / SPEC.name


@pytest.mark.slow  # simulates a 3 s talking take and stabilizes it twice
@pytest.mark.parametrize("chunk_frames", [4096, 128], ids=["whole", "streamed"])
def test_stabilize_finds_the_bone_under_a_sliding_block(small_bone, take, tmp_path, capsys, chunk_frames):
    capture, _ = read_take(take / "capture.usdc")
    block = estimate_rigidity(capture.world_points())
    bone = small_bone.rigid_weights == 1
    assert not np.any((block.weights > 0) & bone)  # rigidity statistics alone lock onto the block

    out = tmp_path / "stabilized.usdc"
    assert main(["stabilize", str(take / "take.usda"), "-o", str(out), "--mask", "all", "--rest", "estimate",
                 "--chunk-frames", str(chunk_frames), "--chunk-overlap", "16", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert "warning" not in json.dumps(summary)
    solved = read_layers([out, take / "capture.usdc"])
    truth = simulate_take(small_bone, SPEC)
    errors = stabilization_errors(*solved.skull(), truth.skull_translate, truth.skull_orient,
                                  truth.quasistatic + truth.offsets, small_bone.face_vertices)
    assert errors["median_vertex_cm"] < 0.005  # the block's frame is 0.1 cm or more off
