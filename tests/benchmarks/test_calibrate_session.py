"""The calibration benchmark's rig and session recipe (benchmarks/arkit_rig.py, calibrate_session.py):
an ARKit-named rig of about 2.7k points that the protocol's held expressions find, and the
issue's 70 takes, none on the test set's held-out 8 Hz platform."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("fast_simplification", reason="arkit_rig.py decimates with fast-simplification (the dev extra has it)")
BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"
sys.path.insert(0, str(BENCHMARKS))

from arkit_rig import arkit_rig  # noqa: E402
from calibrate_session import session_specs  # noqa: E402

from facedyn.motion import parse_platform  # noqa: E402
from facedyn.sim.corpus import held_expressions  # noqa: E402


@pytest.fixture(scope="module")
def rig(shared_data):
    return arkit_rig(shared_data / "ict-facekit" / "ict_face_rig.usdc")


def test_the_arkit_rig_is_ict_decimated_with_arkit_names(rig, shared_data):
    assert 2500 <= rig.point_count <= 2900
    names = set(rig.expression_names)
    assert {"eyeBlinkLeft", "mouthSmileRight", "browInnerUp", "cheekPuff", "jawOpen"} <= names
    assert not any(name.endswith(("_L", "_R")) for name in names) and "cheekPuffLeft" not in names
    assert len(held_expressions(rig)) == 10
    triangles = rig.topology.triangles()
    assert triangles.min() == 0 and triangles.max() == rig.point_count - 1  # every point on a triangle
    assert len(np.unique(np.sort(triangles, axis=1), axis=0)) == len(triangles)  # no triangle twice
    assert len(rig.rigid_vertices) > 0 and len(rig.face_vertices) > 0
    again = arkit_rig(shared_data / "ict-facekit" / "ict_face_rig.usdc")
    assert np.array_equal(again.neutral, rig.neutral) and np.array_equal(again.topology.triangles(), triangles)
    assert all(np.array_equal(again.dense_offsets(name), rig.dense_offsets(name)) for name in rig.expression_names)


def test_the_session_is_seventy_takes_off_the_held_out_platform(rig, shared_data):
    specs = session_specs(rig, shared_data)
    assert len(specs) == 70 and len({s.name for s in specs}) == 70 and len({s.seed for s in specs}) == 70
    platforms = [parse_platform(s.motion.partition(":")[2]) for s in specs if s.motion.startswith("platform")]
    assert len(platforms) == 50 and (8.0, "up") not in platforms and (9.0, "up") not in platforms
    assert {s.motion.rsplit("/", 1)[-1] for s in specs if s.motion.startswith("bvh:")} == {"131_01.bvh", "131_03.bvh"}
    assert [s.name for s in session_specs(rig, shared_data, 2)] == [s.name for s in specs[:14]]
