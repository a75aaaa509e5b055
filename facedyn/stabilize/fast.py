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

MEASURE_FRAMES, MEASURE_VERTICES = 128, 1185  # the problem "auto" times both backends on (the paper's table's vertices)
DECISION = f"{PROGRAM}@{MEASURE_FRAMES}x{MEASURE_VERTICES}"  # the kept decision's name: one per problem measured


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

        self.used_backend = runtime.choose_backend(self.backend, DECISION, _measure_evaluations())
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


def _measure_evaluations():
    """choose_backend's measure: one energy evaluation of a fixed MEASURE_FRAMES x MEASURE_VERTICES
    problem, each backend's evaluator built on its first (untimed, warm-up) call. A fixed problem,
    not the first take's: the decision is kept for the machine, and a solve evaluates one
    evaluator some fifty times, so building it (OpenCL's buffers: 160 ms) is not what to compare.
    The problem is made on the first call only (a kept decision never calls it)."""
    built = {}

    def measure(backend: str) -> None:
        if "problem" not in built:
            random = np.random.default_rng(0)
            points = random.normal(size=(MEASURE_FRAMES, 3, MEASURE_VERTICES)).astype(np.float32)
            rest = random.normal(size=(3, MEASURE_VERTICES)).astype(np.float32)
            velocity = sp.diags([-np.ones(MEASURE_FRAMES), np.ones(MEASURE_FRAMES - 1)], [0, 1]).tocsr()
            built["problem"] = (points, rest, velocity)
            built["motion"] = (np.broadcast_to(np.eye(3), (MEASURE_FRAMES, 3, 3)), np.zeros((MEASURE_FRAMES, 3)))
        if backend not in built:
            built[backend] = _evaluator(backend, *built["problem"], None)
        built[backend](*built["motion"], 1.0, 1.0)

    return measure


def _evaluator(backend: str, points, rest, velocity, weights):
    if backend == "opencl":
        from facedyn.stabilize.opencl import OpenCLEnergy

        return OpenCLEnergy(points, rest, velocity, weights)
    return NumpyEnergy(points, rest, velocity, weights)
