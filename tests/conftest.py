"""Shared fixtures: the real data beside the checkout, and small animated meshes."""
from __future__ import annotations

import os
from pathlib import Path

XDIST_WORKER = os.environ.get("PYTEST_XDIST_WORKER")  # set in each worker process of pytest-xdist (setup.cfg's -n)
if XDIST_WORKER:
    # One worker process per core: a worker's torch and BLAS threads would only wait on the other
    # worker's core. Set before numpy and torch are imported, and inherited by the commands a test runs.
    for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(_name, "1")

import numpy as np
import pytest

import facedyn.usd  # noqa: F401  (registers the USD plugins before any stage is opened)
from usd_fixtures import grid_mesh, write_mesh_cache

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
ICT_RIG = SHARED_DATA / "ict-facekit" / "ict_face_rig.usdc"
TESTS = Path(__file__).resolve().parent
# The modules that take longest (their tests' --durations=0 times summed), longest first.
LONGEST_MODULES = ("test_demo.py", "dynamics/test_response.py", "test_examples.py", "sim/test_tissue.py")


def pytest_collection_modifyitems(config, items):
    """Under xdist, the longest modules first, then those with slow tests, then the rest (each in
    its own order). Workers take whole modules in this order (setup.cfg: --dist loadfile
    --no-loadscope-reorder), so no module as long as the demo starts when the other worker is
    about to run out of work (xdist's own order, by test count, left the one-test demo 98th of 101)."""
    if not XDIST_WORKER:
        return
    slow = {item.path for item in items if item.get_closest_marker("slow")}

    def rank(item) -> int:
        module = item.path.relative_to(TESTS).as_posix() if item.path.is_relative_to(TESTS) else None
        if module in LONGEST_MODULES:
            return LONGEST_MODULES.index(module)
        return len(LONGEST_MODULES) + (item.path not in slow)

    items.sort(key=rank)


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real data not found at {SHARED_DATA} (it lives in ../shared/data beside the checkout)")
    return SHARED_DATA


@pytest.fixture
def grid_cache(tmp_path):
    """A 5-frame animated grid mesh cache and its points."""
    points, counts, indices = grid_mesh()
    frames = np.stack([points + np.array([0.1 * i, 0.0, 0.05 * i], np.float32) for i in range(5)])
    return write_mesh_cache(tmp_path / "grid_cache.usda", frames, counts, indices), frames


@pytest.fixture(scope="session")
def ict_mesh_cache(tmp_path_factory, shared_data):
    """A 24-frame mesh cache animated from the ICT rig (jaw opening while the head turns)."""
    from pxr import Usd, UsdGeom, UsdSkel

    stage = Usd.Stage.Open(str(ICT_RIG))
    skin = UsdGeom.Mesh(stage.GetPrimAtPath("/ICTFace/Skin"))
    neutral = np.asarray(skin.GetPointsAttr().Get(), np.float64)
    jaw = UsdSkel.BlendShape(stage.GetPrimAtPath("/ICTFace/Skin/jawOpen"))
    offsets = np.zeros_like(neutral)
    jaw_indices = jaw.GetPointIndicesAttr().Get()
    jaw_offsets = np.asarray(jaw.GetOffsetsAttr().Get(), np.float64)
    if jaw_indices:
        offsets[np.asarray(jaw_indices)] = jaw_offsets
    else:
        offsets = jaw_offsets
    frames = []
    for i in range(24):
        angle = np.radians(10.0) * np.sin(i / 24 * 2 * np.pi)
        rot = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
        frames.append((neutral + (i / 23) * offsets) @ rot.T + np.array([0.0, 0.2 * i, 0.0]))
    st = UsdGeom.PrimvarsAPI(skin).GetPrimvar("st")
    path = tmp_path_factory.mktemp("ict") / "ict_cache.usdc"
    write_mesh_cache(
        path,
        np.asarray(frames),
        skin.GetFaceVertexCountsAttr().Get(),
        skin.GetFaceVertexIndicesAttr().Get(),
        fps=60.0,
        first_frame=1,
        st=(st.Get(), st.GetIndices()),
    )
    return path, np.asarray(frames, np.float32)
