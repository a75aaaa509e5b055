"""OBJ meshes and sequences: index forms, round trips, topology checks, bad inputs."""
import io

import numpy as np
import pytest

from facedyn.io import obj
from facedyn.io.errors import InputError
from facedyn.progress import Progress

# A quad, a triangle and a pentagon; every face-corner form; relative (negative) indices.
MIXED = """# test
o thing
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0 1.0
v 2 0 0
v 2 1 0 0.5 0.5 0.5
vt 0 0
vt 1 0
vt 1 1
vt 0 1
vn 0 0 1
usemtl skin
s off
f 1/1/1 2/2/1 3/3/1 4/4/1
f 2/2 5/1 3/3
f -5/-4/1 -4/-3/1 -2/-2/1 -1/-1/1 -3/-2/1
"""


def test_index_forms_and_negative_indices(tmp_path):
    path = tmp_path / "mixed.obj"
    path.write_text(MIXED)
    mesh = obj.read_obj(path)
    assert mesh.points.shape == (6, 3) and mesh.points.dtype == np.float32
    np.testing.assert_array_equal(mesh.face_vertex_counts, [4, 3, 5])
    np.testing.assert_array_equal(mesh.face_vertex_indices, [0, 1, 2, 3, 1, 4, 2, 1, 2, 4, 5, 3])
    np.testing.assert_array_equal(mesh.uv_indices, [0, 1, 2, 3, 1, 0, 2, 0, 1, 2, 3, 2])
    np.testing.assert_array_equal(mesh.uv_values, [[0, 0], [1, 0], [1, 1], [0, 1]])


def test_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    mesh = obj.ObjMesh(
        points=rng.normal(size=(7, 3)).astype(np.float32) * 10,
        face_vertex_counts=np.array([3, 4, 5], dtype=np.int32),
        face_vertex_indices=np.array([0, 1, 2, 2, 1, 3, 4, 4, 3, 5, 6, 0], dtype=np.int32),
        uv_values=rng.uniform(0, 7, size=(9, 2)).astype(np.float32),
        uv_indices=np.array([0, 1, 2, 2, 1, 3, 4, 5, 6, 7, 8, 0], dtype=np.int32),
    )
    path = tmp_path / "mesh.obj"
    obj.write_obj(path, mesh)
    back = obj.read_obj(path)
    for field in ("points", "face_vertex_counts", "face_vertex_indices", "uv_values", "uv_indices"):
        np.testing.assert_array_equal(getattr(back, field), getattr(mesh, field), err_msg=field)
    plain = obj.ObjMesh(mesh.points, mesh.face_vertex_counts, mesh.face_vertex_indices)
    obj.write_obj(path, plain)
    back = obj.read_obj(path)
    assert back.uv_values is None and back.uv_indices is None
    np.testing.assert_array_equal(back.face_vertex_indices, mesh.face_vertex_indices)


def _frames(tmp_path, count):
    base = obj.ObjMesh(
        points=np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=np.float32),
        face_vertex_counts=np.array([3, 3], dtype=np.int32),
        face_vertex_indices=np.array([0, 1, 2, 0, 2, 3], dtype=np.int32),
    )
    paths = []
    for frame in range(count):
        path = tmp_path / f"face.{frame + 1}.obj"
        obj.write_obj(path, obj.ObjMesh(base.points + frame, base.face_vertex_counts, base.face_vertex_indices))
        paths.append(path)
    return base, paths


def test_sequence_from_glob_in_natural_order(tmp_path):
    base, paths = _frames(tmp_path, 11)
    sequence = obj.read_obj_sequence(str(tmp_path / "face.*.obj"))
    assert sequence.paths == [str(p) for p in paths]  # face.2 before face.10
    assert sequence.points.shape == (11, 4, 3)
    np.testing.assert_array_equal(sequence.points[10], base.points + 10)
    np.testing.assert_array_equal(sequence.face_vertex_indices, base.face_vertex_indices)
    assert sequence.uvs is None
    progress = Progress(stream=io.StringIO(), interactive=False)
    listed = obj.read_obj_sequence(paths[:3], progress=progress)
    assert listed.points.shape == (3, 4, 3)
    assert progress.stream.getvalue().splitlines()[-1].startswith("read OBJ: 3/3 (100%)")


def test_sequence_uvs_in_performance_form(tmp_path):
    path = tmp_path / "mixed.obj"
    path.write_text(MIXED)
    uvs = obj.read_obj_sequence([path, path]).uvs
    assert uvs.interpolation == "faceVarying"
    np.testing.assert_array_equal(uvs.indices, obj.read_obj(path).uv_indices)


def test_sequence_names_the_first_file_with_another_topology(tmp_path):
    base, paths = _frames(tmp_path, 4)
    for path in paths[2:]:
        path.write_text(path.read_text().replace("f 1 3 4", "f 1 4 3"))
    with pytest.raises(InputError) as error:
        obj.read_obj_sequence(paths)
    assert str(error.value) == f"{paths[2]}: topology differs from the first frame {paths[0]}: face vertex indices differ"
    with pytest.raises(InputError, match="nothing.*.obj: no files match"):
        obj.read_obj_sequence(str(tmp_path / "nothing.*.obj"))


@pytest.mark.parametrize(
    "text, line, reason",
    [
        ("v 0 0 0\nv 1 0 0\nf 1 2\n", 3, "a face needs at least 3 corners, got 2"),
        ("v 0 0 0\nv 1 0 0\nf 1 2 3\n", 3, "vertex index 3 out of range (2 defined so far)"),
        ("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 -4\n", 4, "vertex index -4 out of range (3 defined so far)"),
        ("v 0 0\n", 1, "'v' needs 3 numbers, got 2"),
        ("v 0 0 zero\n", 1, "'v' values must be numbers"),
        ("v 0 0 0\nv 1 0 0\nv 1 1 0\nvt 0 0\nf 1/1 2/1 3\n", 5, "some face corners have texture coordinates and others do not"),
        ("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 x\n", 4, "bad vertex index 'x'"),
        ("v 0 0 0\nv 1 nan 0\n", 2, "'v' values must be finite numbers within ±1e+09"),
        ("v 0 0 0\nv 1 -inf 0\n", 2, "'v' values must be finite numbers within ±1e+09"),
        ("v 0 0 0\nv 1e39 0 0\n", 2, "'v' values must be finite numbers within ±1e+09"),
        ("v 0 0 0\nvt 0.5 inf\n", 2, "'vt' values must be finite numbers within ±1e+09"),
    ],
    ids=["short-face", "past-end", "negative", "short-v", "bad-number", "mixed-uvs", "bad-index", "nan", "inf",
         "float32-overflow", "uv-inf"],
)
def test_malformed_files_name_file_and_line(tmp_path, text, line, reason):
    path = tmp_path / "bad.obj"
    path.write_text(text)
    with pytest.raises(InputError) as error:
        obj.read_obj(path)
    assert str(error.value) == f"{path}, line {line}: {reason}"


def test_missing_and_empty_files(tmp_path):
    with pytest.raises(InputError, match="absent.obj: no such file"):
        obj.read_obj(tmp_path / "absent.obj")
    empty = tmp_path / "empty.obj"
    empty.write_text("# nothing\n")
    with pytest.raises(InputError, match="empty.obj: no vertices"):
        obj.read_obj(empty)
    cloud = tmp_path / "cloud.obj"
    cloud.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    with pytest.raises(InputError) as error:
        obj.read_obj(cloud)
    assert str(error.value) == f"{cloud}: no faces (3 vertices): facedyn needs a polygon mesh, not a point cloud"


def test_latin1_comments_and_names_are_read(tmp_path):
    path = tmp_path / "latin1.obj"
    path.write_bytes("# exporté\no tête\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n".encode("latin-1"))
    np.testing.assert_array_equal(obj.read_obj(path).face_vertex_indices, [0, 1, 2])
