"""The propagation matrix P kept on disk per face, so that a command does not solve it again.

Solving P (facedyn.dynamics.propagate) is one sparse factorization and one right-hand side
per skin sample: 1.5-3 s for the ICT rig's 11,248 points and 344 samples, more than removing
1,000 frames takes. P depends only on the rest mesh, its samples and its rigid vertices, so it
is kept under $XDG_CACHE_HOME/facedyn/propagators/ (else ~/.cache/facedyn/), named by a hash of
exactly those arrays and this facedyn's version, as the bytes the solve gave (a cached P is
the solved one, so results do not depend on the cache). A file that is missing, unreadable or
not a P of that mesh is solved again; a cache that cannot be written leaves P to this process.
The KEEP most recently used files stay, so the cache stays bounded (about 15 MB a face of ICT's size).
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

import numpy as np

from facedyn import __version__
from facedyn.io.files import user_cache_folder, write_atomically

KEEP = 8  # faces whose P stays cached


def folder() -> Path:
    """Where P files are kept: $XDG_CACHE_HOME/facedyn/propagators, else ~/.cache/facedyn/propagators."""
    return user_cache_folder("propagators")


def key(rest_points: np.ndarray, triangles: np.ndarray, samples: np.ndarray, rigid: np.ndarray) -> str:
    """The hash of everything P depends on (the arrays' values and shapes, and the code's version)."""
    digest = hashlib.sha256(f"facedyn {__version__} propagator\n".encode())
    for array, dtype in ((rest_points, np.float64), (triangles, np.int64), (samples, np.int64), (rigid, np.int64)):
        array = np.ascontiguousarray(array, dtype=dtype)
        digest.update(repr(array.shape).encode())
        digest.update(array.tobytes())
    return digest.hexdigest()


def load(name: str, samples: np.ndarray, point_count: int) -> np.ndarray | None:
    """The kept P called `name`, or None when there is none usable: (N, S) float32, finite, the identity at the samples."""
    path = folder() / f"{name}.npy"
    try:
        matrix = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError):
        return None
    shape = (point_count, len(samples))
    if matrix.dtype != np.float32 or matrix.shape != shape or not np.isfinite(matrix).all():
        return None
    if not np.array_equal(matrix[samples], np.eye(len(samples), dtype=np.float32)):
        return None
    try:
        os.utime(path)  # most recently used: the last to be evicted
    except OSError:
        pass
    return matrix


def keep(name: str, matrix: np.ndarray) -> None:
    """Keep P as `name` (atomically), then drop all but the KEEP most recently used; failures are ignored."""
    place = folder()
    try:
        place.mkdir(parents=True, exist_ok=True)
        write_atomically(place / f"{name}.npy", lambda out: np.save(out, np.ascontiguousarray(matrix, np.float32)))
        kept = sorted(place.glob("*.npy"), key=_modified, reverse=True)
        for stale in kept[KEEP:]:
            stale.unlink(missing_ok=True)
    except OSError:
        pass


def _modified(path: Path) -> float:
    try:
        return path.stat().st_mtime
    except OSError:  # removed by another process meanwhile
        return 0.0
