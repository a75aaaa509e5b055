"""OBJ meshes and two-frame sequences, valid and mutated: a mesh or a FacedynError naming the file."""
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import event, given
from hypothesis import strategies as st
from mutate import mutated, only_files, outcome

from facedyn.io import obj


@st.composite
def meshes(draw) -> str:
    """A valid OBJ: points, polygons of 3-5 corners in every corner form (v, v/vt, v//vn,
    v/vt/vn, negative indices), uvs or none, comments and ignored statements."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    points, uvs = draw(st.integers(3, 30)), draw(st.sampled_from([0, 4, 12]))
    form = draw(st.sampled_from(["v", "v/vt", "v//vn", "v/vt/vn"] if uvs else ["v", "v//vn"]))
    lines = ["# fuzz", "o face", "usemtl skin"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in rng.normal(0, 10, (points, 3))]
    lines += [f"vt {u:.6f} {v:.6f}" for u, v in rng.uniform(0, 1, (uvs, 2))]
    lines.append("vn 0 0 1")
    for _ in range(draw(st.integers(1, 20))):
        corners = rng.choice(points, size=rng.integers(3, min(points, 5) + 1), replace=False) + 1
        if rng.uniform() < 0.2:
            corners = corners - points - 1  # the same vertices, counted back from the last
        texture = rng.integers(1, uvs + 1, len(corners)) if uvs else None
        words = {"v": lambda k: f"{corners[k]}", "v/vt": lambda k: f"{corners[k]}/{texture[k]}",
                 "v//vn": lambda k: f"{corners[k]}//1", "v/vt/vn": lambda k: f"{corners[k]}/{texture[k]}/1"}[form]
        lines.append("f " + " ".join(words(k) for k in range(len(corners))))
    return "\n".join(lines) + "\n"


def check_mesh(mesh) -> None:
    counts, indices = mesh.face_vertex_counts, mesh.face_vertex_indices
    assert len(counts) >= 1 and (counts >= 3).all() and counts.sum() == len(indices)
    assert np.isfinite(mesh.points).all() and indices.min() >= 0 and indices.max() < len(mesh.points)
    if mesh.uv_indices is not None:
        assert len(mesh.uv_indices) == len(indices) and 0 <= mesh.uv_indices.min() and mesh.uv_indices.max() < len(mesh.uv_values)
        assert np.isfinite(mesh.uv_values).all()


@given(st.data())
def test_obj_files_give_a_mesh_or_a_clear_error(data):
    raw = data.draw(mutated(data.draw(meshes())))
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "frame.obj"
        path.write_bytes(raw)
        mesh = outcome([path], lambda: obj.read_obj(path))
        if mesh is not None:
            check_mesh(mesh)
        only_files(Path(folder), {"frame.obj"})


@given(st.data())
def test_obj_sequences_with_a_mutated_frame(data):
    """Frame 1 is frame 0 mutated: same topology (read), another one, or broken (refused)."""
    event("file: two-frame sequence")
    text = data.draw(meshes())
    with tempfile.TemporaryDirectory() as folder:
        paths = [Path(folder) / "frame1.obj", Path(folder) / "frame2.obj"]
        paths[0].write_text(text)
        paths[1].write_bytes(data.draw(mutated(text)))
        sequence = outcome(paths, lambda: obj.read_obj_sequence(paths))
        if sequence is not None:
            assert sequence.points.shape[0] == 2 and np.isfinite(sequence.points).all()
        only_files(Path(folder), {"frame1.obj", "frame2.obj"})
