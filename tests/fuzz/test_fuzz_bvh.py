"""BVH files, valid and mutated: a skull trajectory or a FacedynError naming the file.

The files are what `--skull-motion take.bvh` reads (facedyn.motion.from_bvh): performers
in any of the usual units and axes (read with everything inferred), random skeletons of
up to 8 joints (one of them Head) and 30 frames (read with units and axes given or not),
chains up to 3,000 joints deep, and every mutation of mutate.py.
"""
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import event, given
from hypothesis import strategies as st
from mutate import mutated, only_files, outcome

from facedyn import motion

ROTATIONS = ["Xrotation", "Yrotation", "Zrotation"]
POSITIONS = ["Xposition", "Yposition", "Zposition"]
FRAME_TIMES = ["0.0083333", "0.0333333", "0.01", "0.04166667", "0.1", "1"]
SETTINGS = [{}, {"units": 1.0, "up": "+y", "forward": "+z"}, {"units": 5.64}, {"up": "+z"}, {"units": 0.1, "forward": "-x"}]


@st.composite
def skeletons(draw) -> str:
    """A valid BVH: a random joint tree, channels, End Sites and motion."""
    count = draw(st.integers(1, 8))
    parents = [-1] + [draw(st.integers(0, i - 1)) for i in range(1, count)]
    names = [f"J{i}" for i in range(count)]
    names[draw(st.integers(0, count - 1))] = "Head"
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    channels = [draw(st.permutations(POSITIONS + ROTATIONS)) if j == 0 else draw(st.lists(st.sampled_from(ROTATIONS), max_size=3, unique=True))
                for j in range(count)]
    children = {j: [k for k in range(count) if parents[k] == j] for j in range(count)}
    lines = ["HIERARCHY"]

    def block(j, depth):
        pad = "\t" * depth
        lines.append(f"{pad}{'ROOT' if j == 0 else 'JOINT'} {names[j]}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}\tOFFSET " + " ".join(f"{v:.5f}" for v in rng.uniform(-30, 30, 3)))
        if channels[j]:
            lines.append(f"{pad}\tCHANNELS {len(channels[j])} " + " ".join(channels[j]))
        for k in children[j]:
            block(k, depth + 1)
        if not children[j]:
            lines.append(f"{pad}\tEnd Site\n{pad}\t{{\n{pad}\t\tOFFSET 0 {rng.uniform(1, 20):.5f} 0\n{pad}\t}}")
        lines.append(f"{pad}}}")

    block(0, 0)
    frames = draw(st.integers(1, 30))
    columns = sum(len(c) for c in channels)
    values = rng.uniform(-90, 90, (frames, columns)) * draw(st.sampled_from([0.01, 1.0]))
    lines += ["MOTION", f"Frames: {frames}", f"Frame Time: {draw(st.sampled_from(FRAME_TIMES))}"]
    lines += [" ".join(f"{v:.4f}" for v in row) for row in values]
    return "\n".join(lines) + "\n"


@st.composite
def performers(draw) -> str:
    """A valid BVH of a standing performer moving smoothly: a spine up to the Head, legs
    down to toes (or none), in cm, mm, inches or metres, Y-up or Z-up."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    unit_cm = draw(st.sampled_from([1.0, 0.1, 2.54, 100.0]))
    to_file = np.eye(3) if draw(st.booleans()) else np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # Y up, or Z up facing -Y
    joints = [("Hips", None, (0, 0, 0))]  # name, parent, offset in cm (X left, Y up, Z forward)
    for i in range(draw(st.integers(1, 4))):
        joints.append((f"Spine{i}", joints[-1][0], (rng.uniform(-2, 2), rng.uniform(60, 80) / (i + 1), rng.uniform(-2, 2))))
    joints[-1] = ("Head",) + joints[-1][1:]
    if draw(st.booleans()):
        for side in (1, -1):
            joints += [(f"UpLeg{side}", "Hips", (9 * side, -5, 0)), (f"Leg{side}", f"UpLeg{side}", (0, -42, 0)),
                       (f"Foot{side}", f"Leg{side}", (0, -42, 0)), (f"Toe{side}", f"Foot{side}", (0, -6, 12))]
    frames = draw(st.integers(1, 30))
    fps = draw(st.sampled_from([24.0, 30.0, 60.0, 120.0]))
    t = np.arange(frames) / fps
    root = np.stack([np.zeros_like(t), 95 + rng.uniform(0, 3) * np.sin(2 * np.pi * rng.uniform(0.5, 2) * t), 130 * t], axis=1)
    lines = ["HIERARCHY"]
    columns = [(root @ to_file.T / unit_cm).T]

    def block(name, depth):
        _, _, offset = next(j for j in joints if j[0] == name)
        pad = "  " * depth
        lines.append(f"{pad}{'ROOT' if depth == 0 else 'JOINT'} {name}\n{pad}{{")
        lines.append(f"{pad}  OFFSET " + " ".join(f"{v:.5f}" for v in to_file @ np.array(offset, float) / unit_cm))
        lines.append(f"{pad}  CHANNELS " + ("6 Xposition Yposition Zposition " if depth == 0 else "3 ") + "Zrotation Xrotation Yrotation")
        columns.extend(rng.uniform(-10, 10, (3, 1)) * np.sin(2 * np.pi * rng.uniform(0.2, 1.5, (3, 1)) * t))
        kids = [j[0] for j in joints if j[1] == name]
        for kid in kids:
            block(kid, depth + 1)
        if not kids:
            lines.append(f"{pad}  End Site\n{pad}  {{\n{pad}    OFFSET 0 0 {5 / unit_cm:.5f}\n{pad}  }}")
        lines.append(f"{pad}}}")

    block("Hips", 0)
    lines += ["MOTION", f"Frames: {frames}", f"Frame Time: {1 / fps:.7f}"]
    lines += [" ".join(f"{v:.5f}" for v in row) for row in np.vstack(columns).T]
    return "\n".join(lines) + "\n"


@st.composite
def deep_chains(draw) -> str:
    """A chain of up to 3,000 joints, each nested in the last, the Head at its end."""
    depth = draw(st.integers(2, 3000))
    opening = "".join(f"JOINT J{i}\n{{\nOFFSET 0 0.01 0\nCHANNELS 1 Xrotation\n" for i in range(1, depth - 1))
    text = f"HIERARCHY\nROOT J0\n{{\nOFFSET 0 0 0\nCHANNELS 1 Xrotation\n{opening}JOINT Head\n{{\nOFFSET 0 0.01 0\nCHANNELS 1 Xrotation\n"
    return text + "}\n" * depth + "MOTION\nFrames: 2\nFrame Time: 0.01\n" + ("0.001 " * depth + "\n") * 2


def check(raw: bytes, settings: dict) -> None:
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "take.bvh"
        path.write_bytes(raw)
        trajectory = outcome([path], lambda: motion.from_bvh(path, "Head", **settings))
        if trajectory is not None:
            assert trajectory.fps > 0 and trajectory.translate.shape == (trajectory.frame_count, 3)
            assert np.isfinite(trajectory.translate).all() and np.isfinite(trajectory.orient).all()
            np.testing.assert_allclose(np.linalg.norm(trajectory.orient, axis=1), 1.0, atol=1e-6)
        only_files(Path(folder), {"take.bvh"})


@given(st.data())
def test_bvh_files_give_a_trajectory_or_a_clear_error(data):
    kind = data.draw(st.sampled_from(["performer", "random skeleton"]))
    event(f"file: {kind}")
    text = data.draw(performers() if kind == "performer" else skeletons())
    check(data.draw(mutated(text)), data.draw(st.sampled_from(SETTINGS)) if kind == "random skeleton" else {})


@given(st.data())
def test_deeply_nested_bvh_files(data):
    event("file: deep chain")
    check(data.draw(mutated(data.draw(deep_chains()))), {"units": 1.0, "up": "+y", "forward": "+z"})
