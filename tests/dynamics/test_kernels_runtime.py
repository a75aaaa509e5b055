"""The shared OpenCL runtime and the backend choice, kept per device across runs."""
import json
import os
import stat
import time

import pytest
from opencl_marks import requires_opencl

from facedyn.errors import FacedynError
from facedyn.kernels import runtime


@pytest.fixture
def fresh_choices(monkeypatch, tmp_path):
    """A new process: no decisions in memory, an empty decision cache, no override."""
    monkeypatch.setattr(runtime, "_choices", {})
    monkeypatch.setattr(runtime, "_cache_problems", [])
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.delenv(runtime.BACKEND_ENV, raising=False)


@pytest.fixture
def cpu_device(monkeypatch, fresh_choices):
    """A CPU OpenCL device, whether or not this machine has one."""
    monkeypatch.setattr(runtime, "available", lambda: True)
    monkeypatch.setattr(runtime, "is_gpu", lambda: False)
    monkeypatch.setattr(runtime, "device_key", lambda: "Test platform | 1.0 | test CPU | 1.0 | facedyn 0")


def timed(faster):
    """A measure function under which `faster` wins, recording its calls."""
    def measure(backend):
        measure.calls.append(backend)
        time.sleep(0.0 if backend == faster else 0.01)
    measure.calls = []
    return measure


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


def test_auto_measures_once_per_kernel_and_keeps_the_faster(monkeypatch, cpu_device):
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


def test_a_decision_is_kept_across_runs_so_outputs_repeat(monkeypatch, cpu_device):
    assert runtime.choose_backend("auto", "features", timed("opencl")) == "opencl"
    kept = json.loads(runtime.cache_path().read_text())
    entry = kept["Test platform | 1.0 | test CPU | 1.0 | facedyn 0"]["features"]
    assert entry["backend"] == "opencl" and entry["reason"].startswith("measured on a CPU device: numpy ")
    assert stat.S_IMODE(runtime.cache_path().stat().st_mode) == 0o666 & ~_umask()
    # The next run (a new process) would now time NumPy faster: it is not asked.
    monkeypatch.setattr(runtime, "_choices", {})
    again = timed("numpy")
    assert runtime.choose_backend("auto", "features", again) == "opencl" and again.calls == []
    assert runtime.choose_backend("auto", "stretch", again) == "numpy"  # another kernel decides for itself
    # Another device (or driver, or facedyn version) decides afresh.
    monkeypatch.setattr(runtime, "_choices", {})
    monkeypatch.setattr(runtime, "device_key", lambda: "Test platform | 1.0 | test CPU | 2.0 | facedyn 0")
    assert runtime.choose_backend("auto", "features", timed("numpy")) == "numpy"
    assert len(set(json.loads(runtime.cache_path().read_text())) - {"installations"}) == 2


def test_a_kept_numpy_decision_is_read_without_opening_opencl(monkeypatch, cpu_device):
    """OpenCL costs a command 0.1 s to open: a kernel kept on NumPy does not open it again."""
    assert runtime.choose_backend("auto", "features", timed("numpy")) == "numpy"
    assert runtime.choose_backend("auto", "stretch", timed("opencl")) == "opencl"

    def opening():
        raise AssertionError("OpenCL opened")

    monkeypatch.setattr(runtime, "_choices", {})  # a new process on the same installation
    monkeypatch.setattr(runtime, "available", opening)
    assert runtime.choose_backend("auto", "features") == "numpy"
    with pytest.raises(AssertionError, match="OpenCL opened"):
        runtime.choose_backend("auto", "stretch")  # an OpenCL decision needs the device anyway
    monkeypatch.setattr(runtime, "_choices", {})
    monkeypatch.setattr(runtime, "installation", lambda: "another installation")  # e.g. a GPU driver installed
    with pytest.raises(AssertionError, match="OpenCL opened"):
        runtime.choose_backend("auto", "features")


def test_the_installation_changes_with_a_driver(monkeypatch, tmp_path):
    monkeypatch.setenv("OCL_ICD_VENDORS", str(tmp_path))
    (tmp_path / "pocl.icd").write_text("libpocl.so.2\n")
    before = runtime.installation()
    assert runtime.installation() == before
    (tmp_path / "nvidia.icd").write_text("libnvidia-opencl.so.1\n")
    assert runtime.installation() != before


def _umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_the_first_process_to_keep_a_decision_wins(cpu_device):
    """Two runs that measured at once agree on the one kept first."""
    assert runtime._keep("laplacian", "numpy", "measured by the other run") == "numpy"
    assert runtime._keep("laplacian", "opencl", "measured here") == "numpy"
    assert runtime.choose_backend("auto", "laplacian", timed("opencl")) == "numpy"


def test_the_environment_overrides_auto(monkeypatch, cpu_device):
    monkeypatch.setenv(runtime.BACKEND_ENV, "numpy")
    measure = timed("opencl")
    assert runtime.choose_backend("auto", "features", measure) == "numpy" and measure.calls == []
    assert runtime.choose_backend("opencl", "features") == "opencl"  # an explicit request still wins
    assert not runtime.cache_path().exists()
    monkeypatch.setenv(runtime.BACKEND_ENV, "cuda")
    with pytest.raises(FacedynError, match="FACEDYN_BACKEND must be opencl, numpy or auto, got 'cuda'"):
        runtime.choose_backend("auto", "features")


def test_override_to_opencl_without_a_device_is_a_clear_error(monkeypatch, no_device):
    monkeypatch.setenv(runtime.BACKEND_ENV, "OpenCL")
    with pytest.raises(runtime.OpenCLUnavailable, match="no OpenCL platforms"):
        runtime.choose_backend("auto", "features")


def test_a_damaged_or_unwritable_cache_never_stops_a_run(monkeypatch, cpu_device, tmp_path):
    runtime.cache_path().parent.mkdir(parents=True)
    runtime.cache_path().write_text("{not json")
    assert runtime.choose_backend("auto", "features", timed("opencl")) == "opencl"
    assert runtime.backend_report()["cache_problems"][0].startswith(f"ignored {runtime.cache_path()}: not JSON")
    assert json.loads(runtime.cache_path().read_text())  # rewritten whole

    blocked = tmp_path / "a-file"
    blocked.write_text("")
    monkeypatch.setenv("XDG_CACHE_HOME", str(blocked))  # the cache folder cannot be made
    monkeypatch.setattr(runtime, "_choices", {})
    assert runtime.choose_backend("auto", "features", timed("numpy")) == "numpy"
    report = runtime.backend_report()
    assert report["cache_problems"][-1].startswith(f"cannot write {blocked}/facedyn/backends.json")
    assert report["decisions"] == {"features": {"backend": "numpy", "reason": "this process only (nothing was measured)"}}


def test_backend_report(monkeypatch, cpu_device):
    monkeypatch.setattr(runtime, "describe", lambda: "test CPU (Test platform)")
    monkeypatch.setattr(runtime, "unavailable_reason", lambda: None)
    runtime.choose_backend("auto", "features", timed("opencl"))
    monkeypatch.setenv(runtime.BACKEND_ENV, "numpy")
    report = runtime.backend_report()
    assert report == {
        "override": "numpy",
        "device": "test CPU (Test platform)",
        "opencl_unavailable": None,
        "device_key": "Test platform | 1.0 | test CPU | 1.0 | facedyn 0",
        "installation": runtime.installation(),
        "cache": str(runtime.cache_path()),
        "decisions": {"features": {"backend": "opencl", "reason": report["decisions"]["features"]["reason"]}},
        "cache_problems": [],
    }


def test_backend_report_without_a_device(no_device):
    report = runtime.backend_report()
    assert report["device"] is None and report["decisions"] == {}
    assert report["opencl_unavailable"] == "no OpenCL platforms (test)"


@requires_opencl
def test_the_device_key_names_platform_device_driver_and_version():
    key = runtime.device_key()
    device = runtime.runtime().device
    assert device.name.strip() in key and device.driver_version.strip() in key and key.endswith("| facedyn 0.1.0")
