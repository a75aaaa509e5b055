"""The one OpenCL context of the process, the programs built in it, and the backend choice.

Every kernel in facedyn runs through here so that the process opens one context and one
queue (opening a context costs a driver round trip, building a program costs a compiler
run) and so that "no OpenCL here" is one clear error, `OpenCLUnavailable`, which callers
turn into their NumPy path.

Device choice: ``PYOPENCL_CTX`` when set (pyopencl's own convention, e.g. ``0:1``);
otherwise the first GPU of any platform; otherwise the first device of any kind (PoCL's
CPU device on a machine without a GPU).

Backend choice for ``auto`` (see `choose_backend`): NumPy when there is no device; the
OpenCL kernel on a GPU; on a CPU device, whichever of the two ran a representative batch
faster, measured once per kernel and process, and NumPy when the caller gives nothing to
measure (a CPU OpenCL device shares the cores NumPy already uses, so it wins only where
measured).
"""
from __future__ import annotations

import hashlib
import os
import threading
import time
from pathlib import Path
from typing import Callable

from facedyn.errors import FacedynError

BACKENDS = ("auto", "opencl", "numpy")
MEASURE_ROUNDS = 3  # timed runs per backend when auto measures
KERNEL_DIR = Path(__file__).resolve().parent


class OpenCLUnavailable(FacedynError):
    """No usable OpenCL platform, device or compiler in this process."""


class _Runtime:
    def __init__(self, ctx, queue):
        self.context = ctx
        self.queue = queue
        self.device = ctx.devices[0]
        self.programs: dict[str, object] = {}
        self.kernels: dict[tuple[str, str], object] = {}


_lock = threading.Lock()
_runtime: _Runtime | None = None
_failure: str | None = None
_choices: dict[str, str] = {}


def _pick_device(cl):
    devices = [d for p in cl.get_platforms() for d in p.get_devices()]
    if not devices:
        raise OpenCLUnavailable("OpenCL has platforms but no devices")
    gpus = [d for d in devices if d.type & cl.device_type.GPU]
    return (gpus or devices)[0]


def _create() -> _Runtime:
    try:
        import pyopencl as cl
    except ImportError as exc:
        raise OpenCLUnavailable(f"pyopencl is not importable: {exc}") from exc
    try:
        if os.environ.get("PYOPENCL_CTX"):
            ctx = cl.create_some_context(interactive=False)
        else:
            ctx = cl.Context([_pick_device(cl)])
        queue = cl.CommandQueue(ctx)
    except OpenCLUnavailable:
        raise
    except Exception as exc:  # pyopencl raises LogicError/RuntimeError with the driver's reason
        raise OpenCLUnavailable(f"no OpenCL device could be opened: {exc}") from exc
    return _Runtime(ctx, queue)


def runtime() -> _Runtime:
    """The process's context, queue and device, created on first use (thread-safe)."""
    global _runtime, _failure
    if _runtime is not None:
        return _runtime
    with _lock:
        if _runtime is None:
            if _failure is not None:
                raise OpenCLUnavailable(_failure)
            try:
                _runtime = _create()
            except OpenCLUnavailable as exc:
                _failure = str(exc)
                raise
    return _runtime


def available() -> bool:
    """True when an OpenCL device can be used in this process."""
    try:
        runtime()
    except OpenCLUnavailable:
        return False
    return True


def unavailable_reason() -> str | None:
    """Why OpenCL cannot be used here, or None when it can (for test skip messages)."""
    try:
        runtime()
    except OpenCLUnavailable as exc:
        return str(exc)
    return None


def is_gpu() -> bool:
    import pyopencl as cl

    return bool(runtime().device.type & cl.device_type.GPU)


def describe() -> str:
    """'<device> (<platform>)' of the device in use, for logs and benchmark records."""
    device = runtime().device
    return f"{device.name.strip()} ({device.platform.name.strip()})"


def program(name: str, options: tuple[str, ...] = ()):
    """The built program of ``facedyn/kernels/<name>.cl``, built once per source and options."""
    path = KERNEL_DIR / f"{name}.cl"
    if not path.is_file():
        raise ValueError(f"no OpenCL source {path.name} in {KERNEL_DIR}")
    source = path.read_text()
    key = hashlib.sha1((source + "\0" + " ".join(options)).encode()).hexdigest()
    rt = runtime()
    with _lock:
        built = rt.programs.get(key)
        if built is None:
            import pyopencl as cl

            try:
                built = cl.Program(rt.context, source).build(options=list(options))
            except cl.Error as exc:
                raise OpenCLUnavailable(f"{path.name} does not build on {describe()}: {exc}") from exc
            rt.programs[key] = built
    return built


def kernel(name: str, function: str):
    """The kernel ``function`` of program ``name``, created once (setting its arguments and
    enqueueing it is then cheap; callers enqueue from one thread at a time)."""
    prg = program(name)
    rt = runtime()
    key = (name, function)
    with _lock:
        if key not in rt.kernels:
            import pyopencl as cl

            rt.kernels[key] = cl.Kernel(prg, function)
        return rt.kernels[key]


def choose_backend(requested: str, kernel_name: str, measure: Callable[[str], object] | None = None) -> str:
    """Resolve ``'auto' | 'opencl' | 'numpy'`` to ``'opencl'`` or ``'numpy'``.

    ``'opencl'`` raises `OpenCLUnavailable` where there is no device. For ``'auto'`` the
    rule is in the module docstring; ``measure(backend)`` runs a small representative batch
    on that backend. It is called once per backend to warm up (program build, allocations)
    and then MEASURE_ROUNDS times more, interleaved; the backend with the faster best run
    is remembered per ``kernel_name`` for the rest of the process.
    """
    if requested not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {requested!r}")
    if requested == "numpy":
        return "numpy"
    if requested == "opencl":
        runtime()
        return "opencl"
    if not available():
        return "numpy"
    if kernel_name in _choices:
        return _choices[kernel_name]
    if is_gpu():
        choice = "opencl"
    elif measure is None:
        choice = "numpy"
    else:
        timings = {"numpy": float("inf"), "opencl": float("inf")}
        for backend in timings:
            measure(backend)  # warm-up: program build, allocations
        for _ in range(MEASURE_ROUNDS):  # interleaved, best of each: robust to a busy machine
            for backend in timings:
                start = time.perf_counter()
                measure(backend)
                timings[backend] = min(timings[backend], time.perf_counter() - start)
        choice = min(timings, key=timings.get)
    _choices[kernel_name] = choice
    return choice
