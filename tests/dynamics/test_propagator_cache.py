"""The on-disk cache of solved propagation matrices: the same P as the solve, solved again when the file is not one."""
import os

import numpy as np
import pytest
from synthetic_face import curved_sheet, top_rows

from facedyn.dynamics import propagate, propagator_cache
from facedyn.dynamics.propagate import build_propagator
from facedyn.dynamics.samples import farthest_point_samples

ROWS, COLS = 16, 14


@pytest.fixture
def cache_home(tmp_path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    return tmp_path / "cache" / "facedyn" / "propagators"


def sheet(sample_count: int = 12):
    pts, topo = curved_sheet(ROWS, COLS)
    tri = topo.triangles()
    rigid = top_rows(ROWS, COLS, 2)
    samples = farthest_point_samples(pts, tri, sample_count, np.setdiff1d(np.arange(len(pts)), rigid))
    return pts, tri, samples, rigid


def no_solve(monkeypatch):
    def refuse(*args):
        raise AssertionError("P was solved, not read from the cache")
    monkeypatch.setattr(propagate, "_solve", refuse)


def test_a_cached_p_is_the_solved_one_bit_for_bit_and_is_not_solved_again(cache_home, monkeypatch):
    pts, tri, samples, rigid = sheet()
    solved = build_propagator(pts, tri, samples, rigid)
    first = build_propagator(pts, tri, samples, rigid, cache=True)
    assert len(list(cache_home.glob("*.npy"))) == 1
    no_solve(monkeypatch)
    again = build_propagator(pts, tri, samples, rigid, cache=True)
    for prop in (first, again):
        assert prop.matrix.dtype == np.float32 and np.array_equal(prop.matrix, solved.matrix)
        assert np.array_equal(prop.rigid, solved.rigid) and np.array_equal(prop.inverse_mass, solved.inverse_mass)


def test_another_mesh_samples_or_rigid_region_is_another_entry(cache_home):
    pts, tri, samples, rigid = sheet()
    keys = {propagator_cache.key(pts, tri, samples, rigid), propagator_cache.key(pts * 1.001, tri, samples, rigid),
            propagator_cache.key(pts, tri, samples[:-1], rigid), propagator_cache.key(pts, tri, samples, rigid[:-1])}
    assert len(keys) == 4


@pytest.mark.parametrize("damage", ["garbage", "shape", "not identity", "non-finite"])
def test_a_file_that_is_not_this_meshs_p_is_solved_again_and_replaced(cache_home, damage):
    pts, tri, samples, rigid = sheet()
    solved = build_propagator(pts, tri, samples, rigid, cache=True)
    path = cache_home / f"{propagator_cache.key(pts, tri, samples, rigid)}.npy"
    wrong = solved.matrix.copy()
    if damage == "garbage":
        path.write_bytes(b"not a numpy file")
    else:
        if damage == "shape":
            wrong = wrong[:, :-1]
        elif damage == "not identity":
            wrong[samples[0], 0] = 0.5
        else:
            wrong[-1, -1] = np.nan
        np.save(path, wrong)
    again = build_propagator(pts, tri, samples, rigid, cache=True)
    assert np.array_equal(again.matrix, solved.matrix)
    assert np.array_equal(np.load(path), solved.matrix)  # the good P kept in its place


def test_an_unwritable_cache_leaves_p_to_this_process(tmp_path, monkeypatch):
    blocked = tmp_path / "file"
    blocked.write_text("a file where the cache folder would go")
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocked))
    pts, tri, samples, rigid = sheet()
    assert np.array_equal(build_propagator(pts, tri, samples, rigid, cache=True).matrix,
                          build_propagator(pts, tri, samples, rigid).matrix)


def test_only_the_most_recently_used_faces_stay(cache_home, monkeypatch):
    monkeypatch.setattr(propagator_cache, "KEEP", 2)
    pts, tri, samples, rigid = sheet()
    for count in (8, 9, 10):
        build_propagator(pts, tri, samples[:count], rigid, cache=True)
        path = cache_home / f"{propagator_cache.key(pts, tri, samples[:count], rigid)}.npy"
        if path.exists():  # used in this order, whatever the file system's clock resolution
            os.utime(path, (1000 + count, 1000 + count))
    kept = {path.stem for path in cache_home.glob("*.npy")}
    assert kept == {propagator_cache.key(pts, tri, samples[:count], rigid) for count in (9, 10)}
