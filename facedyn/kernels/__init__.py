"""OpenCL kernels with their NumPy twins, and the choice of backend (pyopencl loads only when a kernel runs)."""
from facedyn.lazy_exports import lazy_exports

_PUBLIC = {
    "backend_report": "runtime",
}

__all__, __getattr__ = lazy_exports(__name__, _PUBLIC)
