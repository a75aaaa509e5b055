"""Wavefront OBJ meshes and mesh sequences, the usual exchange format of tracked faces.

Reads ``v``, ``vt`` and ``f`` statements (corners as v, v/vt, v//vn or v/vt/vn; negative
indices count back from the latest vertex; polygons of any size). Normals, groups,
materials and other statements are ignored. Arrays come out in USD's form: float32
points, faceVertexCounts/Indices, and texture coordinates as faceVarying indexed uvs.
"""
from __future__ import annotations

import glob
import re
from collections.abc import Sequence
from dataclasses import dataclass
from os import PathLike
from typing import TYPE_CHECKING

import numpy as np

from facedyn.io.errors import InputError
from facedyn.io.files import read_lines
from facedyn.performance import UVs

if TYPE_CHECKING:
    from facedyn.progress import Progress

MAX_COORDINATE = 1e9
"""The largest magnitude of a coordinate (anything beyond is garbage, or inf in float32)."""


@dataclass(frozen=True, eq=False)
class ObjMesh:
    """One mesh: points, polygon topology and optional faceVarying indexed uvs."""

    points: np.ndarray  # (N, 3) float32
    face_vertex_counts: np.ndarray  # (P,) int32
    face_vertex_indices: np.ndarray  # (sum(counts),) int32
    uv_values: np.ndarray | None = None  # (K, 2) float32
    uv_indices: np.ndarray | None = None  # (sum(counts),) int32, one per face corner


@dataclass(frozen=True, eq=False)
class ObjSequence:
    """Frames of one topology: every frame's points, and the topology and uvs they share."""

    points: np.ndarray  # (F, N, 3) float32
    face_vertex_counts: np.ndarray  # (P,) int32
    face_vertex_indices: np.ndarray  # (sum(counts),) int32
    uv_values: np.ndarray | None  # (K, 2) float32, from the first frame
    uv_indices: np.ndarray | None  # (sum(counts),) int32
    paths: list[str]

    @property
    def uvs(self) -> UVs | None:
        """The uvs as a Performance holds them (faceVarying, indexed), None without uvs."""
        return _performance_uvs(self.uv_values, self.uv_indices)


def read_obj(path: str | PathLike) -> ObjMesh:
    """Parse an OBJ file; any problem is an InputError naming the file and line."""
    path = str(path)
    lines = read_lines(path)
    points: list[list[float]] = []
    uvs: list[list[float]] = []
    counts: list[int] = []
    corners: list[int] = []
    uv_corners: list[int] = []
    faces_have_uvs: bool | None = None
    for number, line in enumerate(lines, 1):
        words = line.split()
        if not words:
            continue
        if words[0] == "v":
            points.append(_floats(path, number, words, 3))
        elif words[0] == "vt":
            uvs.append(_floats(path, number, words, 2))
        elif words[0] == "f":
            if len(words) < 4:
                raise InputError(path, f"a face needs at least 3 corners, got {len(words) - 1}", number)
            face = [_corner(path, number, word, len(points), len(uvs)) for word in words[1:]]
            with_uvs = face[0][1] is not None
            if any((uv is not None) != with_uvs for _, uv in face) or faces_have_uvs not in (None, with_uvs):
                raise InputError(path, "some face corners have texture coordinates and others do not", number)
            faces_have_uvs = with_uvs
            counts.append(len(face))
            corners.extend(vertex for vertex, _ in face)
            if with_uvs:
                uv_corners.extend(uv for _, uv in face)
    if not points:
        raise InputError(path, "no vertices")
    if not counts:
        raise InputError(path, f"no faces ({len(points)} vertices): facedyn needs a polygon mesh, not a point cloud")
    return ObjMesh(
        points=np.array(points, dtype=np.float32),
        face_vertex_counts=np.array(counts, dtype=np.int32),
        face_vertex_indices=np.array(corners, dtype=np.int32),
        uv_values=np.array(uvs, dtype=np.float32).reshape(-1, 2) if faces_have_uvs else None,
        uv_indices=np.array(uv_corners, dtype=np.int32) if faces_have_uvs else None,
    )


def _floats(path: str, line: int, words: list[str], count: int) -> list[float]:
    """The first `count` numbers after the keyword (v may carry w or colours, vt a w)."""
    if len(words) < count + 1:
        raise InputError(path, f"'{words[0]}' needs {count} numbers, got {len(words) - 1}", line)
    try:
        values = [float(word) for word in words[1 : count + 1]]
    except ValueError:
        raise InputError(path, f"'{words[0]}' values must be numbers", line) from None
    if not all(abs(value) <= MAX_COORDINATE for value in values):
        raise InputError(path, f"'{words[0]}' values must be finite numbers within ±{MAX_COORDINATE:g}", line)
    return values


def _corner(path: str, line: int, word: str, points: int, uvs: int) -> tuple[int, int | None]:
    """One face corner as 0-based (vertex, uv or None), checked against what precedes it."""
    parts = word.split("/")
    if len(parts) > 3 or not parts[0]:
        raise InputError(path, f"bad face corner {word!r}", line)
    vertex = _index(path, line, parts[0], points, "vertex")
    uv = _index(path, line, parts[1], uvs, "texture coordinate") if len(parts) > 1 and parts[1] else None
    return vertex, uv


def _index(path: str, line: int, text: str, available: int, what: str) -> int:
    try:
        index = int(text)
    except ValueError:
        raise InputError(path, f"bad {what} index {text!r}", line) from None
    resolved = index - 1 if index > 0 else available + index
    if index == 0 or not 0 <= resolved < available:
        raise InputError(path, f"{what} index {index} out of range ({available} defined so far)", line)
    return resolved


def write_obj(path: str | PathLike, mesh: ObjMesh) -> None:
    """Write `mesh` (float32 precision, 1-based indices) so that read_obj gives it back."""
    counts = np.asarray(mesh.face_vertex_counts)
    starts = np.concatenate([[0], np.cumsum(counts)])
    vertex = np.asarray(mesh.face_vertex_indices) + 1
    with_uvs = mesh.uv_values is not None and mesh.uv_indices is not None
    uv = np.asarray(mesh.uv_indices) + 1 if with_uvs else None
    with open(path, "w") as handle:
        handle.write("# facedyn\n")
        np.savetxt(handle, np.asarray(mesh.points, dtype=np.float32), fmt="v %.9g %.9g %.9g")
        if with_uvs:
            np.savetxt(handle, np.asarray(mesh.uv_values, dtype=np.float32).reshape(-1, 2), fmt="vt %.9g %.9g")
        for begin, end in zip(starts[:-1], starts[1:]):
            if with_uvs:
                corners = " ".join(f"{v}/{t}" for v, t in zip(vertex[begin:end], uv[begin:end]))
            else:
                corners = " ".join(map(str, vertex[begin:end]))
            handle.write(f"f {corners}\n")


class ObjFrames:
    """An OBJ sequence read a range of files at a time, so a long one is never whole in memory.

    The first file gives the topology and uvs every frame shares; `read` parses the files of
    any range of frames, and the first file whose topology (point count, polygons, uv
    indices) differs from the first frame's is an InputError naming it.
    """

    def __init__(self, paths: Sequence[str | PathLike]):
        self.paths = [str(path) for path in paths]
        if not self.paths:
            raise ValueError("an OBJ sequence needs at least one path")
        self.first = read_obj(self.paths[0])

    def __len__(self) -> int:
        return len(self.paths)

    @property
    def uvs(self) -> UVs | None:
        """The first frame's uvs as a Performance holds them (faceVarying, indexed), None without uvs."""
        return _performance_uvs(self.first.uv_values, self.first.uv_indices)

    def read(self, start: int, stop: int, progress: Progress | None = None) -> np.ndarray:
        """(stop - start, N, 3) float32: the points of files start..stop-1, each checked against the first."""
        points = np.empty((stop - start,) + self.first.points.shape, dtype=np.float32)
        for row, path in enumerate(self.paths[start:stop]):
            mesh = self.first if start + row == 0 else read_obj(path)
            difference = _topology_difference(self.first, mesh)
            if difference:
                raise InputError(path, f"topology differs from the first frame {self.paths[0]}: {difference}")
            points[row] = mesh.points
            if progress is not None:
                progress.advance()
        return points


def read_obj_sequence(
    paths_or_glob: str | PathLike | Sequence[str | PathLike], progress: Progress | None = None
) -> ObjSequence:
    """Read frames that share one topology (all at once; ObjFrames reads a range at a time).

    A glob is sorted naturally (frame2 before frame10). The first file whose topology
    differs from the first frame's is an InputError naming it.
    """
    if isinstance(paths_or_glob, (str, PathLike)):
        pattern = str(paths_or_glob)
        paths = sorted(glob.glob(pattern), key=_natural_key)
        if not paths:
            raise InputError(pattern, "no files match")
    else:
        paths = [str(path) for path in paths_or_glob]
        if not paths:
            raise ValueError("read_obj_sequence needs at least one path")
    frames = ObjFrames(paths)
    if progress is not None:
        progress.start("read OBJ", len(paths))
    points = frames.read(0, len(frames), progress)
    if progress is not None:
        progress.finish()
    first = frames.first
    return ObjSequence(points, first.face_vertex_counts, first.face_vertex_indices, first.uv_values, first.uv_indices, paths)


def _performance_uvs(values: np.ndarray | None, indices: np.ndarray | None) -> UVs | None:
    return None if values is None else UVs(values, indices, "faceVarying")


def _topology_difference(a: ObjMesh, b: ObjMesh) -> str:
    """What differs between two meshes' topologies, or '' when nothing does."""
    if len(a.points) != len(b.points):
        return f"{len(b.points)} points instead of {len(a.points)}"
    if not np.array_equal(a.face_vertex_counts, b.face_vertex_counts):
        return "polygon sizes differ"
    if not np.array_equal(a.face_vertex_indices, b.face_vertex_indices):
        return "face vertex indices differ"
    if (a.uv_indices is None) != (b.uv_indices is None) or (
        a.uv_indices is not None and not np.array_equal(a.uv_indices, b.uv_indices)
    ):
        return "uv indices differ"
    return ""


def _natural_key(text: str) -> list:
    return [int(part) if part.isdigit() else part for part in re.split(r"(\d+)", text)]
