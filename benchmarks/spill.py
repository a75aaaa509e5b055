"""Corpora spilled to disk: a standard corpus with performances (40-50k frames of an
11k-point face, three arrays per frame) outgrows 24 GiB of memory, so the accuracy
benchmarks keep it memory-mapped in a scratch folder that is removed at exit."""
from __future__ import annotations

import atexit
import shutil
import tempfile
from pathlib import Path

import numpy as np


def scratch_folder() -> Path:
    """A fresh folder under the system's temp folder, removed when the process exits."""
    folder = Path(tempfile.mkdtemp(prefix="facedyn-bench-"))
    atexit.register(shutil.rmtree, folder, ignore_errors=True)
    return folder


def spill(path: Path, array: np.ndarray) -> np.ndarray:
    """`array` saved to `path` and read back memory-mapped (read-only)."""
    np.save(path, array)
    return np.load(path, mmap_mode="r")
