"""The fast mode-pursuit stage solver: analytic gradients and L-BFGS for fixed iterations.

Same energy and schedule as the reference (facedyn.stabilize.reference); the difference
is engineering: the per-vertex work is a handful of whole-array float32 passes (NumPy,
or the OpenCL kernel where it is faster), the spline chain is differentiated by hand,
and L-BFGS (facedyn.stabilize.lbfgs) runs ``iterations`` iterations per stage at about
one evaluation each (fewer only once the energy has stalled at float32 resolution).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from facedyn.geometry import dualquat
from facedyn.kernels import runtime
from facedyn.stabilize import lbfgs
from facedyn.stabilize.energy import NumpyEnergy
from facedyn.stabilize.objective import ControlObjective
from facedyn.stabilize.opencl import PROGRAM

MEASURE_FRAMES = 128  # frames of the chunk that "auto" times both backends on


class FastSolver:
    """backend: "opencl" (kernels/stabilize_energy.cl), "numpy", or "auto": the faster of
    the two on this machine (facedyn.kernels.runtime.choose_backend), NumPy without a device."""

    name = "fast"
    energy_is_numpy = True  # its energies are NumpyEnergy's (OpenCL's kernels are its tested twin): no re-evaluation

    def __init__(self, backend: str = "auto"):
        if backend not in runtime.BACKENDS:
            raise ValueError(f"backend must be one of {runtime.BACKENDS}, got {backend!r}")
        self.backend = backend
        self.used_backend: str | None = None  # what "auto" resolved to, once bound

    def bind(self, points: np.ndarray, rest: np.ndarray, velocity: sp.spmatrix, weights: np.ndarray | None):
        """An energy evaluator for one chunk: points (F, 3, N), rest (3, N) in problem units."""

        def measure(backend: str) -> None:
            f = min(len(points), MEASURE_FRAMES)
            evaluator = _evaluator(backend, points[:f], rest, sp.csr_matrix(velocity)[:f, :f], weights)
            evaluator(np.broadcast_to(np.eye(3), (f, 3, 3)), np.zeros((f, 3)), 1.0, 1.0)

        self.used_backend = runtime.choose_backend(self.backend, PROGRAM, measure)
        return _evaluator(self.used_backend, points, rest, velocity, weights)

    def minimize(self, energy, basis: sp.spmatrix, controls: np.ndarray, width_pos: float, width_vel: float,
                 iterations: int, memo: dict):
        """Run one stage; returns (controls (n, 8), final energy, energy evaluations).

        memo (one per chunk, kept by the caller across stages) carries L-BFGS's
        inverse-Hessian scale from stage to stage, so restarts need no step-length search.
        The evaluator is rebased on the stage's starting motion (float32 accuracy, see
        facedyn.stabilize.energy).
        """
        objective = ControlObjective(basis, energy, width_pos, width_vel)
        energy.rebase(*dualquat.to_rotation_translation(objective.transforms(controls)))
        x0 = np.asarray(controls, dtype=np.float64).ravel()
        scale = memo.get("scale")
        if scale is not None:
            scale *= (width_pos / memo["width_pos"]) ** 2  # the penalty's curvature goes as 1 / width^2
        result = lbfgs.minimize(objective, x0, iterations, scale)
        memo.update(scale=result.scale, width_pos=width_pos)
        return result.x.reshape(-1, 8), result.fun, result.evaluations


def _evaluator(backend: str, points, rest, velocity, weights):
    if backend == "opencl":
        from facedyn.stabilize.opencl import OpenCLEnergy

        return OpenCLEnergy(points, rest, velocity, weights)
    return NumpyEnergy(points, rest, velocity, weights)
