"""Stabilization: the rigid skull motion of a tracked face (papers/001, mode pursuit) and
the simple baselines (three-point, Procrustes, robust ICP). Arrays in, arrays out.

The public names load on first use (PEP 562): importing a submodule such as
`facedyn.stabilize.chunks` (the stabilize command's declaration does) must not pull in the
solvers and SciPy, which every command's start-up would then pay for.
"""
from facedyn.lazy_exports import lazy_exports

_PUBLIC = {"METHODS": "api", "SOLVERS": "api", "StabilizeResult": "api", "stabilize": "api",
           "REFERENCE_FPS": "schedule", "Schedule": "schedule"}

__all__, __getattr__ = lazy_exports(__name__, _PUBLIC)
