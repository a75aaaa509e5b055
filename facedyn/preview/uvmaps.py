"""Per-frame uv offset maps: per-vertex vectors baked into UDIM tiles of OpenEXR images.

Compositors and DCC shaders apply the dynamics offsets as textures, so each frame's
skull-space offsets (cm) are baked into uv space: RGB = xyz offset, A = coverage. Which
triangle and barycentrics each texel takes depends only on the uv layout, so it is
rasterized once per topology (`UVBaker`) into a sparse texel-by-vertex weight matrix;
baking is then one sparse product for several frames at once.

Tiles follow the UDIM convention: uv tile (u_tile, v_tile) is 1001 + u_tile + 10 * v_tile
and every triangle belongs to the tile holding its uv centroid. Texel (x, y) of a
res x res tile has its centre at u = u_tile + (x + 0.5) / res, v = v_tile + 1 - (y + 0.5) / res
(image rows run top to bottom, v bottom to top).
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from facedyn.performance import Topology, UVs
from facedyn.preview.images import write_image
from facedyn.preview.raster import rasterize

# Frames are baked together in groups whose maps stay near this many floats (128 MB).
_CHUNK_FLOATS = 1 << 25


@dataclass
class _Tile:
    weights: sp.csr_matrix  # (res * res, N): each covered texel's barycentric weights
    coverage: np.ndarray  # (res * res,) float32, 1 where a triangle covers the texel


def _corner_uv_indices(topology: Topology, uvs: UVs) -> np.ndarray:
    """Index into `uvs.values` for every face-vertex corner, (sum(counts),)."""
    corners = len(topology.face_vertex_indices)
    if uvs.interpolation == "faceVarying":
        element = np.arange(corners)
    elif uvs.interpolation == "vertex":
        element = np.asarray(topology.face_vertex_indices, dtype=np.int64)
    else:
        raise ValueError(f"uv interpolation must be 'faceVarying' or 'vertex', got {uvs.interpolation!r}")
    elements = int(element.max()) + 1 if corners else 0
    if uvs.indices is None:
        index = element
    else:
        indices = np.asarray(uvs.indices, dtype=np.int64)
        if len(indices) < elements:
            raise ValueError(f"{uvs.interpolation} uvs need {elements} indices, got {len(indices)}")
        index = indices[element]
    if corners and (index.min() < 0 or index.max() >= len(uvs.values)):
        raise ValueError(f"uv indices must lie in [0, {len(uvs.values)}), got [{index.min()}, {index.max()}]")
    return index


def udim(u_tile: np.ndarray, v_tile: np.ndarray) -> np.ndarray:
    """UDIM tile number(s) of integer uv tile coordinates."""
    return 1001 + np.asarray(u_tile) + 10 * np.asarray(v_tile)


class UVBaker:
    """The uv layout of one topology, rasterized once into per-tile texel lookups."""

    def __init__(self, topology: Topology, uvs: UVs, resolution: int = 1024):
        if resolution < 1:
            raise ValueError(f"resolution must be positive, got {resolution}")
        values = np.asarray(uvs.values, dtype=np.float64)
        if values.ndim != 2 or values.shape[1] != 2:
            raise ValueError(f"uv values must be (K, 2), got {values.shape}")
        self.resolution = int(resolution)
        self.point_count = topology.point_count
        tri_vertices = topology.triangles().astype(np.int64)
        # Fan-triangulating corner numbers instead of vertex indices gives each triangle's
        # face-vertex corners, which is where faceVarying uvs live.
        corners = np.arange(len(topology.face_vertex_indices), dtype=np.int32)
        tri_corners = Topology(topology.face_vertex_counts, corners).triangles()
        tri_uv = values[_corner_uv_indices(topology, uvs)[tri_corners]]  # (T, 3, 2)
        tile = np.floor(tri_uv.mean(axis=1)).astype(np.int64)  # (T, 2)
        if len(tile) and (tile[:, 0].min() < 0 or tile[:, 0].max() > 9 or tile[:, 1].min() < 0):
            raise ValueError(
                f"uvs must lie in UDIM tiles (0 <= u < 10, v >= 0), got u tiles {tile[:, 0].min()}..{tile[:, 0].max()}"
                f" and v tiles {tile[:, 1].min()}..{tile[:, 1].max()}"
            )
        self.tiles: dict[int, _Tile] = {}
        numbers = udim(tile[:, 0], tile[:, 1])
        for number in np.unique(numbers):
            members = np.flatnonzero(numbers == number)
            u_tile, v_tile = tile[members[0]]
            local = tri_uv[members] - [u_tile, v_tile]
            xy = np.stack([local[..., 0], 1.0 - local[..., 1]], axis=-1).reshape(-1, 2) * resolution
            frags = rasterize(xy, None, np.arange(3 * len(members)).reshape(-1, 3), resolution, resolution)
            texels = resolution * resolution
            rows = np.repeat(frags.pixel, 3)
            cols = tri_vertices[members[frags.triangle]].ravel()
            weights = sp.csr_matrix((frags.bary.ravel(), (rows, cols)), shape=(texels, self.point_count))
            coverage = np.zeros(texels, dtype=np.float32)
            coverage[frags.pixel] = 1.0
            self.tiles[int(number)] = _Tile(weights, coverage)

    def bake(self, values: np.ndarray) -> dict[int, np.ndarray]:
        """UDIM -> (F, res, res, 4) float32 maps: RGB = the interpolated value, A = coverage.

        `values` are per-vertex vectors, (N, 3) for one frame or (F, N, 3).
        """
        vals = np.asarray(values, dtype=np.float32)
        if vals.ndim == 2:
            vals = vals[None]
        if vals.ndim != 3 or vals.shape[1:] != (self.point_count, 3):
            n = self.point_count
            raise ValueError(f"values must be ({n}, 3) or (F, {n}, 3), got {np.shape(values)}")
        frames, res = len(vals), self.resolution
        by_vertex = vals.transpose(1, 0, 2).reshape(self.point_count, 3 * frames)
        maps = {}
        for number, tile in self.tiles.items():
            baked = (tile.weights @ by_vertex).reshape(res * res, frames, 3)
            out = np.empty((frames, res * res, 4), dtype=np.float32)
            out[..., :3] = baked.transpose(1, 0, 2)
            out[..., 3] = tile.coverage
            maps[number] = out.reshape(frames, res, res, 4)
        return maps

    def frames_per_chunk(self) -> int:
        """How many frames `write_offset_maps` bakes at once, to bound memory."""
        return max(1, _CHUNK_FLOATS // (4 * self.resolution**2 * max(len(self.tiles), 1)))


def offset_map_path(folder: str | os.PathLike, name: str, udim_number: int, frame: int) -> Path:
    """`folder/name.<UDIM>.####.exr`, e.g. offsets.1001.0042.exr."""
    return Path(folder) / f"{name}.{udim_number}.{frame:04d}.exr"


def write_offset_maps(
    folder: str | os.PathLike,
    name: str,
    baker: UVBaker,
    offsets: np.ndarray,
    frames: np.ndarray,
    fps: float,
    version: str,
    pixel_type: str = "half",
) -> list[Path]:
    """Bake (F, N, 3) skull-space offsets (cm) and write one EXR per tile and frame.

    Each file is written atomically and carries facedyn:frame, facedyn:fps,
    facedyn:units ("cm"), facedyn:space ("skull") and facedyn:version in its header.
    `pixel_type` is "half" or "float". Returns the paths written, frame by frame.
    """
    if not Path(folder).is_dir():
        raise ValueError(f"cannot write offset maps: folder {folder} does not exist")
    if pixel_type not in ("half", "float"):
        raise ValueError(f"pixel_type must be 'half' or 'float', got {pixel_type!r}")
    if not name or Path(name).name != name:
        raise ValueError(f"name must be a plain file name stem, got {name!r}")
    offs = np.asarray(offsets)
    frame_numbers = np.asarray(frames, dtype=np.float64)
    n = baker.point_count
    if offs.ndim != 3 or offs.shape[1:] != (n, 3) or frame_numbers.shape != (len(offs),):
        raise ValueError(f"offsets must be (F, {n}, 3) with F frame numbers, got {offs.shape} and {frame_numbers.shape}")
    if not np.all(frame_numbers == np.round(frame_numbers)):
        raise ValueError("offset maps are named by integer frame numbers; got fractional frames")
    paths = []
    step = baker.frames_per_chunk()
    for start in range(0, len(offs), step):
        maps = baker.bake(offs[start : start + step])
        for i, frame in enumerate(frame_numbers[start : start + step].astype(int)):
            attributes = {
                "facedyn:frame": int(frame),
                "facedyn:fps": float(fps),
                "facedyn:units": "cm",
                "facedyn:space": "skull",
                "facedyn:version": str(version),
            }
            for number, tile_maps in maps.items():
                path = offset_map_path(folder, name, number, int(frame))
                paths.append(write_image(path, tile_maps[i], attributes, ("R", "G", "B", "A"), pixel_type))
    return paths
