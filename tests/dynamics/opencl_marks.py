"""The skip marker for tests that need an OpenCL device."""
import pytest

from facedyn.kernels import runtime

_reason = runtime.unavailable_reason()
requires_opencl = pytest.mark.skipif(_reason is not None, reason=f"no OpenCL device in this process: {_reason}")
BACKENDS = ["numpy", pytest.param("opencl", marks=requires_opencl)]
