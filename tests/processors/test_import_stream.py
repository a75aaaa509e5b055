"""`import` streams its source (issue 19): a take longer than a chunk gives what reading it whole gives.

"Whole" is the import with one chunk (the take fits in it), byte for byte, and the cubic
spline through every sample of the take (scipy), for the resampled and gap-filled cases.
"""
import os
from pathlib import Path

import numpy as np
import pytest
from pxr import Gf, Usd, UsdGeom
from scipy.interpolate import make_interp_spline

from facedyn.cli import main
from facedyn.io.obj import ObjMesh, write_obj
from facedyn.processors import import_take
from facedyn.usd import clips
from facedyn.usd.source import read_usd_mesh
from facedyn.usd.take import read_take

from usd_fixtures import grid_mesh, write_mesh_cache

CHUNK = 16  # frames per chunk in the streamed imports (the takes are 10 to 20 chunks long)


def _motion(count: int, seed: int) -> np.ndarray:
    """(count, 9, 3) float32: a 3x3 grid wandering smoothly (no two frames alike)."""
    points, _, _ = grid_mesh(3)
    walk = np.cumsum(np.random.default_rng(seed).normal(0, 0.05, (count, len(points), 3)), axis=0)
    return (points[None] * 3 + walk).astype(np.float32)


def _import(source, output: Path, *flags, chunk: int | None = None, monkeypatch=None) -> int:
    if chunk is not None:
        monkeypatch.setattr(import_take, "CHUNK_FRAMES", chunk)
    return main(["import", *map(str, source if isinstance(source, list) else [source]), "-o", str(output), "-q", *map(str, flags)])


def _streamed_and_whole(tmp_path, monkeypatch, source, *flags, resampled=False):
    """Import `source` in CHUNK-frame chunks and in one chunk, and return the streamed take.

    Both must have the same frames and points: the same bytes, or when resampled (a spline
    through each chunk's samples and its context, see CubicResampler) within float32 rounding.
    """
    for name, chunk in (("whole", 1 << 20), ("streamed", CHUNK)):
        (tmp_path / name).mkdir()
        assert _import(source, tmp_path / name / "capture.usdc", *flags, chunk=chunk, monkeypatch=monkeypatch) == 0
    streamed, whole = (read_take(tmp_path / name / "take.usda")[0] for name in ("streamed", "whole"))
    np.testing.assert_array_equal(streamed.frames, whole.frames)
    if resampled:
        assert (np.abs(streamed.points - whole.points) <= np.spacing(np.abs(whole.points))).all()
    else:
        for name in ("capture.usdc", "take.usda"):
            assert (tmp_path / "streamed" / name).read_bytes() == (tmp_path / "whole" / name).read_bytes()
    return streamed


def _spline(seconds: np.ndarray, values: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """The whole take's cubic spline (not-a-knot) at `grid`: what import resampled before it streamed."""
    return make_interp_spline(seconds, values.astype(np.float64), k=3, axis=0)(np.minimum(grid, seconds[-1])).astype(np.float32)


def test_streamed_usd_import_equals_reading_it_whole(tmp_path, monkeypatch):
    """Metres, Z up, under an animated transform: converted per chunk as the whole take was."""
    values = _motion(300, 1)
    _, counts, indices = grid_mesh(3)
    source = write_mesh_cache(tmp_path / "cache.usdc", values, counts, indices, up_axis="Z", meters_per_unit=0.01 * 2.5)
    stage = Usd.Stage.Open(str(source))
    op = UsdGeom.Xformable(stage.GetPrimAtPath("/Cache/Geo")).AddTranslateOp()
    for i in range(300):
        op.Set(Gf.Vec3d(0.01 * i, 1.0, -2.0), 1001 + i)
    stage.Save()
    take = _streamed_and_whole(tmp_path, monkeypatch, source)
    np.testing.assert_array_equal(take.frames, np.arange(1001, 1301))
    world = (values.astype(np.float64) + np.stack([0.01 * np.arange(300), np.ones(300), -2 * np.ones(300)], 1)[:, None]) * 2.5
    expected = np.stack([world[..., 0], world[..., 2], -world[..., 1]], axis=-1)  # Z up -> Y up
    np.testing.assert_allclose(take.points, expected, atol=1e-4)


def test_streamed_resampling_equals_the_whole_takes_spline(tmp_path, monkeypatch):
    """A 30 fps capture with gaps, resampled to 120 fps: each chunk from the samples it needs."""
    keep = np.setdiff1d(np.arange(200), [5, 6, 7, 40, 41, 120])
    values = _motion(200, 2)[keep]
    _, counts, indices = grid_mesh(3)
    source = write_mesh_cache(tmp_path / "at30.usdc", values, counts, indices, fps=30.0, first_frame=0)
    stage = Usd.Stage.Open(str(source))
    attr = stage.GetPrimAtPath("/Cache/Geo/Face").GetAttribute("points")
    samples = [attr.Get(t) for t in attr.GetTimeSamples()]
    attr.Clear()
    for frame, value in zip(keep, samples):
        attr.Set(value, 1001.0 + frame)
    stage.Save()
    take = _streamed_and_whole(tmp_path, monkeypatch, source, "--fps", 120, resampled=True)
    grid = (1001 + keep[0]) / 30.0 + np.arange(len(take.frames)) / 120.0
    np.testing.assert_array_equal(take.frames, 1001 + np.arange(len(take.frames)))
    assert len(take.frames) == (keep[-1] - keep[0]) * 4 + 1 and len(take.frames) > 40 * CHUNK
    assert (np.abs(take.points - _spline((1001 + keep) / 30.0, values, grid)) <= np.spacing(np.abs(take.points))).all()


def test_streamed_obj_sequence_with_a_gap_equals_reading_it_whole(tmp_path, monkeypatch):
    values = _motion(180, 3)
    _, counts, indices = grid_mesh(3)
    folder = tmp_path / "objs"
    folder.mkdir()
    present = np.setdiff1d(np.arange(180), np.arange(70, 75))
    for frame in present:
        write_obj(folder / f"face.{1001 + frame}.obj", ObjMesh(values[frame], counts, indices))
    take = _streamed_and_whole(tmp_path, monkeypatch, folder, "--fps", 24, "--units", 0.1, resampled=True)
    np.testing.assert_array_equal(take.frames, np.arange(1001, 1181))
    scaled = (values[present] * 0.1).astype(np.float32)
    expected = _spline((1001 + present) / 24.0, scaled, 1001 / 24.0 + np.arange(180) / 24.0)
    assert (np.abs(take.points - expected) <= np.spacing(np.abs(expected))).all()
    np.testing.assert_allclose(take.points[present], values[present] * 0.1, atol=1e-6)  # read frames come back


def test_a_long_import_is_written_as_clips_and_reads_the_same(tmp_path, monkeypatch):
    values = _motion(120, 4)
    _, counts, indices = grid_mesh(3)
    source = write_mesh_cache(tmp_path / "cache.usdc", values, counts, indices)
    monkeypatch.setattr(clips, "CLIP_THRESHOLD", 50)
    assert _import(source, tmp_path / "capture.usdc", chunk=CHUNK, monkeypatch=monkeypatch) == 0
    (folder,) = tmp_path.glob("capture.*.clips")
    assert len(list(folder.glob("capture.*.usdc"))) == -(-120 // CHUNK)
    take, _ = read_take(tmp_path / "take.usda")
    np.testing.assert_array_equal(take.frames, np.arange(1001, 1121))
    np.testing.assert_array_equal(take.points, values)


@pytest.mark.parametrize("clip_threshold", [5000, 50])
def test_a_fault_in_a_later_chunk_leaves_nothing_behind(tmp_path, monkeypatch, capsys, clip_threshold):
    values = _motion(120, 5)
    values[100, 3, 1] = np.nan
    _, counts, indices = grid_mesh(3)
    source = write_mesh_cache(tmp_path / "nan.usdc", values, counts, indices)
    monkeypatch.setattr(clips, "CLIP_THRESHOLD", clip_threshold)
    out = tmp_path / "out"
    out.mkdir()
    assert _import(source, out / "capture.usdc", chunk=CHUNK, monkeypatch=monkeypatch) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "nan.usdc" in err[0] and "NaN or infinite values at time 1101" in err[0]
    # No layer, no take root, no clips, no temporary files, and not the take root's lock file either:
    # the failed run made the root's lock and nobody else holds it.
    assert os.listdir(out) == []


def test_a_static_mesh_and_a_first_frame_read_canonical(tmp_path):
    """What `actor --from neutral` reads: an animated mesh's first frame, or a static mesh's value, in cm, Y up."""
    values = _motion(3, 6)
    _, counts, indices = grid_mesh(3)
    source = write_mesh_cache(tmp_path / "mesh.usdc", values, counts, indices, up_axis="Z", meters_per_unit=0.1)
    y_up_cm = lambda p: np.stack([p[..., 0], p[..., 2], -p[..., 1]], axis=-1) * 10.0  # noqa: E731
    first = read_usd_mesh(source, first_frame_only=True)
    np.testing.assert_allclose(first.points, y_up_cm(values[:1]), atol=1e-5)
    assert first.frames.tolist() == [1001.0]
    stage = Usd.Stage.Open(str(source))
    attr = stage.GetPrimAtPath("/Cache/Geo/Face").GetAttribute("points")
    value = attr.Get(1002)
    attr.Clear()
    attr.Set(value)  # a static mesh: a default value, no time samples
    stage.Save()
    static = read_usd_mesh(source, first_frame_only=True)
    np.testing.assert_allclose(static.points, y_up_cm(values[1:2]), atol=1e-5)
    assert static.frames.tolist() == [0.0]
