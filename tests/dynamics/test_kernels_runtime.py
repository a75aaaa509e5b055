"""The shared OpenCL runtime and the backend choice."""
import time

import pytest
from opencl_marks import requires_opencl

from facedyn.errors import FacedynError
from facedyn.kernels import runtime


@pytest.fixture
def fresh_choices(monkeypatch):
    monkeypatch.setattr(runtime, "_choices", {})


@pytest.fixture
def no_device(monkeypatch, fresh_choices):
    monkeypatch.setattr(runtime, "_runtime", None)
    monkeypatch.setattr(runtime, "_failure", "no OpenCL platforms (test)")


def test_numpy_is_always_available_and_bad_names_are_rejected(fresh_choices):
    assert runtime.choose_backend("numpy", "anything") == "numpy"
    with pytest.raises(ValueError, match="backend must be one of"):
        runtime.choose_backend("cuda", "anything")


def test_without_a_device_auto_is_numpy_and_opencl_is_a_clear_error(no_device):
    assert runtime.choose_backend("auto", "features") == "numpy"
    with pytest.raises(runtime.OpenCLUnavailable, match="no OpenCL platforms"):
        runtime.choose_backend("opencl", "features")
    assert issubclass(runtime.OpenCLUnavailable, FacedynError)
    assert not runtime.available() and "no OpenCL" in runtime.unavailable_reason()


def test_auto_measures_once_per_kernel_and_keeps_the_faster(monkeypatch, fresh_choices):
    monkeypatch.setattr(runtime, "available", lambda: True)
    monkeypatch.setattr(runtime, "is_gpu", lambda: False)
    calls = []

    def measure(backend):
        calls.append(backend)
        time.sleep(0.02 if backend == "numpy" else 0.0)

    assert runtime.choose_backend("auto", "k1", measure) == "opencl"
    assert runtime.choose_backend("auto", "k1", measure) == "opencl"
    rounds = ["numpy", "opencl"] * runtime.MEASURE_ROUNDS
    assert calls == ["numpy", "opencl"] + rounds  # warm-ups, then interleaved timed runs, once

    # one slow run (a busy machine) does not flip the choice: the best run of each counts
    slow = iter([0.0, 0.0, 0.05] + [0.0] * 10)

    def hiccup(backend):
        time.sleep(next(slow) if backend == "opencl" else 0.01)

    assert runtime.choose_backend("auto", "k4", hiccup) == "opencl"
    assert runtime.choose_backend("auto", "k2") == "numpy"  # CPU device, nothing to measure
    monkeypatch.setattr(runtime, "is_gpu", lambda: True)
    assert runtime.choose_backend("auto", "k3") == "opencl"  # the GPU rule


@requires_opencl
def test_one_context_and_programs_built_once():
    assert runtime.runtime() is runtime.runtime()
    assert runtime.program("laplacian") is runtime.program("laplacian")
    assert runtime.kernel("laplacian", "csr_apply_frames") is runtime.kernel("laplacian", "csr_apply_frames")
    assert runtime.describe()
    with pytest.raises(ValueError, match="no OpenCL source"):
        runtime.program("no_such_kernel")
