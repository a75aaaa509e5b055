"""Scratch space for the benchmarks.

Corpora spilled to disk: a standard corpus with performances (40-50k frames of an 11k-point
face, three arrays per frame) outgrows 24 GiB of memory, so the accuracy benchmarks keep it
memory-mapped in a scratch folder that is removed at exit. The long-take and import
benchmarks write takes of many GB into a work folder (``--workdir``, kept with ``--keep``)."""
from __future__ import annotations

import argparse
import atexit
import shutil
import tempfile
from contextlib import contextmanager
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


def work_folder_arguments(parser: argparse.ArgumentParser) -> None:
    """--workdir (where the work folder goes; created if missing) and --keep (leave it behind)."""
    parser.add_argument("--workdir", type=Path, default=None, help="put the work folder here (default: the system's temp folder)")
    parser.add_argument("--keep", action="store_true", help="leave the work folder behind")


@contextmanager
def work_folder(prefix: str, args: argparse.Namespace):
    """A fresh folder under args.workdir (made if missing), removed afterwards unless args.keep."""
    if args.workdir is not None:
        args.workdir.mkdir(parents=True, exist_ok=True)
    folder = Path(tempfile.mkdtemp(prefix=prefix, dir=args.workdir))
    try:
        yield folder
    finally:
        if not args.keep:
            shutil.rmtree(folder, ignore_errors=True)
