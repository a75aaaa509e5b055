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
faster (a CPU OpenCL device shares the cores NumPy already uses, so it wins only where
measured), and NumPy when the caller gives nothing to measure. The two backends agree to
rounding, not to the bit, so a decision that changed from run to run would change outputs
from run to run: each decision is made once per machine, device and facedyn version and
kept in a small JSON file (`cache_path`, under $XDG_CACHE_HOME or ~/.cache), so the same
inputs give the same bytes on every run. ``FACEDYN_BACKEND=opencl|numpy`` overrides
``auto`` for the process; `backend_report` says what was chosen, why and where it is kept.

Opening OpenCL costs a command a tenth of a second (pyopencl's import, the platforms, a
context), so a kernel whose kept decision is NumPy does not open it: the file also maps a
fingerprint of the OpenCL installation (`installation`, read from files without opening
OpenCL) to the device key it opened, and a process whose installation is known reads the
decision through it.
"""
from __future__ import annotations

import contextlib
import glob
import hashlib
import importlib.util
import json
import os
import platform
import threading
import time
from pathlib import Path
from typing import Callable

from facedyn import __version__
from facedyn.errors import FacedynError
from facedyn.io.errors import InputError
from facedyn.io.files import read_text, user_cache_folder, write_atomically

BACKENDS = ("auto", "opencl", "numpy")
BACKEND_ENV = "FACEDYN_BACKEND"
MEASURE_ROUNDS = 3  # timed runs per backend when auto measures
KERNEL_DIR = Path(__file__).resolve().parent
_CACHE_MAX_BYTES = 1 << 20
_INSTALLATIONS = "installations"  # the decision file's {installation fingerprint: device key}
_STEERING_ENV = ("PYOPENCL_CTX", "OCL_ICD_VENDORS", "OCL_ICD_FILENAMES", "POCL_DEVICES", "CUDA_VISIBLE_DEVICES",
                 "ROCR_VISIBLE_DEVICES")  # variables that change which device a process opens


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
_choices: dict[str, str] = {}  # this process's decisions, by kernel name
_cache_problems: list[str] = []  # why the decision cache could not be read or written


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

    ``'opencl'`` raises `OpenCLUnavailable` where there is no device. ``'auto'`` follows
    FACEDYN_BACKEND when it is set, else the decision kept for this device and kernel,
    else makes it by the rule in the module docstring and keeps it: ``measure(backend)``
    runs a small representative batch on that backend, once per backend to warm up
    (program build, allocations) and then MEASURE_ROUNDS times more, interleaved, and the
    backend with the faster best run wins. Without `measure` a CPU device gets NumPy for
    this process only, so that a later measured call still decides.
    """
    if requested not in BACKENDS:
        raise ValueError(f"backend must be one of {BACKENDS}, got {requested!r}")
    if requested == "auto":
        requested = _override() or "auto"
    if requested == "numpy":
        return "numpy"
    if requested == "opencl":
        runtime()
        return "opencl"
    if kernel_name not in _choices and _kept_without_opening(kernel_name) == "numpy":
        _choices[kernel_name] = "numpy"
    if _choices.get(kernel_name) == "numpy":
        return "numpy"
    if not available():
        return "numpy"
    if kernel_name not in _choices:
        kept = _kept_decisions().get(kernel_name)
        if kept is not None:
            _choices[kernel_name] = kept["backend"]
            _note_installation()
        elif is_gpu():
            _choices[kernel_name] = _keep(kernel_name, "opencl", "a GPU device")
        elif measure is None:
            _choices[kernel_name] = "numpy"
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
            reason = "measured on a CPU device: " + ", ".join(f"{b} {t * 1e3:.2f} ms" for b, t in timings.items())
            _choices[kernel_name] = _keep(kernel_name, choice, reason)
    return _choices[kernel_name]


def _override() -> str | None:
    """FACEDYN_BACKEND as a backend name, None when unset or 'auto'."""
    value = os.environ.get(BACKEND_ENV, "").strip().lower()
    if value in ("", "auto"):
        return None
    if value not in BACKENDS:
        raise FacedynError(f"{BACKEND_ENV} must be opencl, numpy or auto, got {os.environ[BACKEND_ENV]!r}")
    return value


def cache_path() -> Path:
    """Where backend decisions are kept: $XDG_CACHE_HOME/facedyn/backends.json, else ~/.cache/facedyn/."""
    return user_cache_folder("backends.json")


def device_key() -> str:
    """What a kept decision is valid for: the platform, device and driver, and this facedyn."""
    device = runtime().device
    parts = (device.platform.name, device.platform.version, device.name, device.driver_version)
    return " | ".join(str(part).strip() for part in parts) + f" | facedyn {__version__}"


def installation() -> str:
    """A fingerprint of what decides which device this process opens, read without opening
    OpenCL: the host, this facedyn, the variables that steer the choice, the ICD vendor files
    and the libraries they name, pyopencl's package, and the GPU device nodes. A driver
    installed, updated or removed, or a GPU added, gives another fingerprint."""
    parts = [platform.node(), f"facedyn {__version__}"]
    parts += [f"{name}={os.environ.get(name, '')}" for name in _STEERING_ENV]
    vendors = Path(os.environ.get("OCL_ICD_VENDORS") or "/etc/OpenCL/vendors")
    for icd in sorted(vendors.glob("*.icd")) if vendors.is_dir() else [vendors]:
        try:
            library = icd.read_text(errors="replace").strip()
        except OSError:
            library = None
        parts.append(f"{icd}: {library} {_stamp(library)}")
    spec = importlib.util.find_spec("pyopencl")
    parts.append(f"pyopencl {_stamp(spec.origin if spec else None)}")
    parts += sorted(glob.glob("/dev/nvidia*") + glob.glob("/dev/dri/*") + glob.glob("/dev/kfd"))
    return hashlib.sha256("\n".join(str(part) for part in parts).encode()).hexdigest()[:32]


def _stamp(path: str | None) -> str:
    """A file's size and modification time, or why there is none (a bare library name: the linker's to find)."""
    try:
        info = os.stat(path)
    except (OSError, TypeError, ValueError):
        return "-"
    return f"{info.st_size} {info.st_mtime_ns}"


def _kept_without_opening(kernel_name: str) -> str | None:
    """The backend kept for `kernel_name` on the device this installation opened before, or None when unknown."""
    data = _read_cache()
    known = data.get(_INSTALLATIONS)
    key = known.get(installation()) if isinstance(known, dict) else None
    entries = data.get(key) if isinstance(key, str) else None
    entry = entries.get(kernel_name) if isinstance(entries, dict) else None
    return entry.get("backend") if isinstance(entry, dict) else None


def _note_installation() -> None:
    """Map this installation to its device key in the decision file, if it is not yet (see `installation`)."""
    known = _read_cache().get(_INSTALLATIONS)
    if isinstance(known, dict) and known.get(installation()) == device_key():
        return
    _update_cache(lambda data: None)


def _update_cache(change: Callable[[dict], str | None]) -> str | None:
    """Apply `change` to the decision file under its lock and write it back, with this installation mapped
    to its device key; returns what `change` returned. A file that cannot be written is a problem reported
    by backend_report, and None."""
    path = cache_path()
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with _locked(path.with_name(path.name + ".lock")):
            data = _read_cache()
            result = change(data)
            known = data.get(_INSTALLATIONS)
            if not isinstance(known, dict):
                known = data[_INSTALLATIONS] = {}
            known[installation()] = device_key()
            text = json.dumps(data, indent=1, sort_keys=True) + "\n"
            write_atomically(path, lambda out: out.write(text.encode()))
            return result
    except OSError as exc:
        _problem(f"cannot write {path}: {exc.strerror or exc}; decisions last for this process only")
    return None


def _read_cache() -> dict:
    """The whole decision file, {} when it is absent or unreadable (the reason is kept)."""
    path = cache_path()
    try:
        data = json.loads(read_text(path, _CACHE_MAX_BYTES))
    except InputError as exc:
        if exc.reason != "no such file":
            _problem(f"ignored {exc}")
        return {}
    except ValueError as exc:
        _problem(f"ignored {path}: not JSON ({exc})")
        return {}
    if not isinstance(data, dict):
        _problem(f"ignored {path}: not a JSON object")
        return {}
    return data


def _kept_decisions() -> dict[str, dict]:
    """This device's kept decisions, {kernel: {"backend", "reason"}}, valid entries only."""
    entries = _read_cache().get(device_key())
    if not isinstance(entries, dict):
        return {}
    return {name: entry for name, entry in entries.items()
            if isinstance(entry, dict) and entry.get("backend") in ("opencl", "numpy")}


def _keep(kernel_name: str, backend: str, reason: str) -> str:
    """Keep a decision for this device, unless another process kept one first (then that
    one is returned, so that concurrent runs agree); a cache that cannot be written
    leaves the decision to this process (see backend_report)."""
    def change(data: dict) -> str:
        entries = data.get(device_key())
        if not isinstance(entries, dict):
            entries = data[device_key()] = {}
        kept = entries.get(kernel_name)
        if isinstance(kept, dict) and kept.get("backend") in ("opencl", "numpy"):
            return kept["backend"]
        entries[kernel_name] = {"backend": backend, "reason": reason}
        return backend

    return _update_cache(change) or backend


def _problem(message: str) -> None:
    if message not in _cache_problems:
        _cache_problems.append(message)


@contextlib.contextmanager
def _locked(lock_path: Path):
    """An exclusive lock between processes (POSIX), so two runs do not both decide."""
    try:
        import fcntl
    except ImportError:  # Windows: the atomic rename still keeps the file whole
        yield
        return
    with open(lock_path, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def backend_report() -> dict:
    """What `usdfacedyn env` prints: the override, the device, and every decision kept for
    it (backend and why), plus this process's unkept ones and any cache problems."""
    report = {
        "override": os.environ.get(BACKEND_ENV) or None,
        "device": None,
        "opencl_unavailable": unavailable_reason(),
        "device_key": None,
        "installation": installation(),
        "cache": str(cache_path()),
        "decisions": {},
        "cache_problems": [],
    }
    if report["opencl_unavailable"] is None:
        report["device"] = describe()
        report["device_key"] = device_key()
        report["decisions"] = _kept_decisions()
        for name, backend in _choices.items():
            report["decisions"].setdefault(name, {"backend": backend, "reason": "this process only (nothing was measured)"})
    report["cache_problems"] = list(_cache_problems)
    return report
