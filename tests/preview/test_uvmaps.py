"""uv offset maps: texel lookups, linear fields, UDIM tiles, faceVarying seams, EXR files."""
import os

import numpy as np
import OpenImageIO as oiio
import pytest

from facedyn.performance import Topology, UVs
from facedyn.preview.uvmaps import UVBaker, offset_map_path, write_offset_maps

RES = 64


def quad_grid(nx, ny, u_range=(0.0, 2.0), v_range=(0.0, 1.0)):
    """A quad mesh whose uvs (indexed faceVarying, no seams) are a regular grid: (topology, uvs, uv per vertex)."""
    u, v = np.meshgrid(np.linspace(*u_range, nx), np.linspace(*v_range, ny))
    uv = np.stack([u, v], -1).reshape(-1, 2)
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1))
    a = (j * nx + i).ravel()
    quads = np.stack([a, a + 1, a + nx + 1, a + nx], 1).astype(np.int32)
    topology = Topology(np.full(len(quads), 4, np.int32), quads.ravel())
    return topology, UVs(uv.astype(np.float32), quads.ravel().copy(), "faceVarying"), uv


def texel_centres(udim):
    u_tile, v_tile = (udim - 1001) % 10, (udim - 1001) // 10
    y, x = np.mgrid[0:RES, 0:RES]
    return u_tile + (x + 0.5) / RES, v_tile + 1 - (y + 0.5) / RES


def test_a_linear_field_is_reproduced_at_texel_centres_in_both_tiles():
    topology, uvs, uv = quad_grid(9, 5)  # u in [0, 2] with a vertex column on u = 1
    baker = UVBaker(topology, uvs, RES)
    assert sorted(baker.tiles) == [1001, 1002]
    field = np.stack([uv[:, 0], uv[:, 1], 3 * uv[:, 0] - 2 * uv[:, 1] + 0.5], 1)
    maps = baker.bake(np.stack([field, 2 * field]))
    for udim, tile in maps.items():
        assert tile.shape == (2, RES, RES, 4)
        u, v = texel_centres(udim)
        assert (tile[..., 3] == 1).all()  # the grid covers both tiles completely
        np.testing.assert_allclose(tile[0, ..., 0], u, atol=2e-6)
        np.testing.assert_allclose(tile[0, ..., 1], v, atol=2e-6)
        np.testing.assert_allclose(tile[0, ..., 2], 3 * u - 2 * v + 0.5, atol=1e-5)
        np.testing.assert_allclose(tile[1, ..., :3], 2 * tile[0, ..., :3], atol=1e-5)


def test_facevarying_seam_sends_one_vertex_to_two_tiles_and_leaves_gaps_uncovered():
    # Two triangles sharing the edge (1, 2); the second is laid out in tile 1011 (v tile 1).
    topology = Topology(np.array([3, 3], np.int32), np.array([0, 1, 2, 2, 1, 3], np.int32))
    values = np.array([[0.1, 0.1], [0.9, 0.1], [0.1, 0.9], [0.1, 1.1], [0.9, 1.1], [0.1, 1.9], [0.3, 1.3]], np.float32)
    uvs = UVs(values, np.array([0, 1, 2, 5, 3, 4], np.int32), "faceVarying")
    baker = UVBaker(topology, uvs, RES)
    assert sorted(baker.tiles) == [1001, 1011]
    per_vertex = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0], [5.0, 5.0, 5.0]])
    maps = baker.bake(per_vertex)
    for udim, corner_uvs in ((1001, values[[0, 1, 2]]), (1011, values[[5, 3, 4]])):
        tile = maps[udim][0]
        covered = tile[..., 3] > 0
        assert 0.2 < covered.mean() < 0.45  # a triangle of area 0.32 of the tile
        assert (tile[~covered] == 0).all()
        # the vertex-2 corner sits at uv (0.1, 0.9) in 1001 and at (0.1, 1.9) in 1011
        x, y = int(0.1 * RES) + 1, int((1 - 0.9) * RES) + 2
        assert tile[y, x, 2] > 0.9
    covered = maps[1001][0][maps[1001][0][..., 3] > 0]
    np.testing.assert_allclose(covered[:, :3].sum(-1), 1.0, atol=1e-5)  # barycentric weights sum to one


def test_vertex_interpolated_uvs_bake_like_facevarying_ones():
    topology, uvs, uv = quad_grid(5, 5, (0.0, 1.0), (0.0, 1.0))
    field = np.column_stack([uv, uv[:, :1] * uv[:, 1:]])
    by_corner = UVBaker(topology, uvs, RES).bake(field)[1001]
    by_vertex = UVBaker(topology, UVs(uv.astype(np.float32), None, "vertex"), RES).bake(field)[1001]
    np.testing.assert_array_equal(by_corner, by_vertex)


def test_exr_files_are_named_by_udim_and_frame_and_carry_metadata(tmp_path):
    topology, uvs, uv = quad_grid(9, 5)
    baker = UVBaker(topology, uvs, RES)
    rng = np.random.default_rng(1)
    offsets = rng.normal(0, 0.2, (3, len(uv), 3)).astype(np.float32)
    paths = write_offset_maps(tmp_path, "offsets", baker, offsets, [41, 42, 43], 96.0, "0.1.0")
    assert sorted(os.listdir(tmp_path)) == sorted(
        f"offsets.{udim}.{frame:04d}.exr" for udim in (1001, 1002) for frame in (41, 42, 43)
    )
    assert paths[2] == offset_map_path(tmp_path, "offsets", 1001, 42) == tmp_path / "offsets.1001.0042.exr"
    inp = oiio.ImageInput.open(str(tmp_path / "offsets.1002.0042.exr"))
    spec = inp.spec()
    pixels = inp.read_image(oiio.FLOAT)
    inp.close()
    assert spec.format == oiio.HALF and tuple(spec.channelnames) == ("R", "G", "B", "A")
    assert (spec.width, spec.height) == (RES, RES)
    assert spec.getattribute("facedyn:frame") == 42
    assert spec.getattribute("facedyn:fps") == 96.0
    assert spec.getattribute("facedyn:units") == "cm"
    assert spec.getattribute("facedyn:space") == "skull"
    assert spec.getattribute("facedyn:version") == "0.1.0"
    want = baker.bake(offsets[1])[1002][0]
    np.testing.assert_allclose(pixels, want, atol=2e-3)  # half precision
    write_offset_maps(tmp_path, "full", baker, offsets[:1], [7], 96.0, "0.1.0", pixel_type="float")
    inp = oiio.ImageInput.open(str(tmp_path / "full.1001.0007.exr"))
    assert inp.spec().format == oiio.FLOAT
    np.testing.assert_array_equal(inp.read_image(oiio.FLOAT), baker.bake(offsets[0])[1001][0])
    inp.close()


def test_bad_input_is_refused(tmp_path):
    topology, uvs, uv = quad_grid(3, 3)
    baker = UVBaker(topology, uvs, 8)
    offsets = np.zeros((1, len(uv), 3), np.float32)
    with pytest.raises(ValueError, match=r"values must be \(9, 3\)"):
        baker.bake(np.zeros((9, 2)))
    with pytest.raises(ValueError, match="fractional frames"):
        write_offset_maps(tmp_path, "o", baker, offsets, [1.5], 24.0, "v")
    with pytest.raises(ValueError, match="F frame numbers"):
        write_offset_maps(tmp_path, "o", baker, offsets, [1, 2], 24.0, "v")
    with pytest.raises(ValueError, match=r"offsets must be \(F, 9, 3\)"):
        write_offset_maps(tmp_path, "o", baker, offsets[:, :4], [1], 24.0, "v")
    with pytest.raises(ValueError, match=f"folder {tmp_path / 'missing'} does not exist"):
        write_offset_maps(tmp_path / "missing", "o", baker, offsets, [1], 24.0, "v")
    with pytest.raises(ValueError, match="UDIM tiles"):
        UVBaker(topology, UVs(uvs.values - 1.0, uvs.indices, "faceVarying"), 8)
    with pytest.raises(ValueError, match="interpolation"):
        UVBaker(topology, UVs(uvs.values, uvs.indices, "uniform"), 8)
    with pytest.raises(ValueError, match="uv indices"):
        UVBaker(topology, UVs(uvs.values[:3], uvs.indices, "faceVarying"), 8)
    assert os.listdir(tmp_path) == []
