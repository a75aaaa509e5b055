"""OpenBLAS's threads, held to one where the work is many small products.

NumPy and SciPy each ship their own OpenBLAS, which splits every product over the cores. For
small matrices (a simulator step's supernodes, the linear response's modal fit) the threads
only spin, and on a machine shared with other work that spinning slows the whole several
times: calibrate's test (a 4-take session, its time in the response's modal fit) took 171 s
on a loaded 2-core machine with two threads and 23.5 s with one (22.5 s and 24.5 s idle).
"""
from __future__ import annotations

import ctypes
from contextlib import contextmanager


@contextmanager
def single_threaded_blas():
    """Run the block with OpenBLAS on one thread (in this thread only), then restore.

    Uses OpenBLAS's thread-local setter in each loaded copy (numpy and
    scipy ship their own); where there is none (other BLAS, other OS) it does nothing.
    """
    setters = []
    try:
        with open("/proc/self/maps") as maps:
            paths = sorted({line.split()[-1] for line in maps if "openblas" in line.lower() and "/" in line})
    except OSError:
        paths = []
    for path in paths:
        try:
            setter = ctypes.CDLL(path).openblas_set_num_threads_local
        except (OSError, AttributeError):
            continue
        setter.restype, setter.argtypes = ctypes.c_int, [ctypes.c_int]
        setters.append(setter)
    previous = [setter(1) for setter in setters]
    try:
        yield
    finally:
        for setter, count in zip(setters, previous):
            setter(count)
