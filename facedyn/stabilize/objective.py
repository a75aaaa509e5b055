"""Mode-pursuit energy as a function of the spline's control dual quaternions.

The chain controls -> SDLB -> per-frame (R_f, t_f) is small (frames x 8 numbers) and is
differentiated by hand (facedyn.geometry.sdlb, dualquat); the big per-vertex part is
delegated to an energy evaluator (NumPy or OpenCL) that returns dE/dR_f and dE/dt_f.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from facedyn.geometry import dualquat, sdlb


class ControlObjective:
    """f(controls) = E(SDLB(controls)) and its gradient, on flat control vectors."""

    def __init__(self, basis: sp.spmatrix, energy, width_pos: float, width_vel: float):
        self.basis = sp.csr_matrix(basis)
        self.energy = energy
        self.width_pos = width_pos
        self.width_vel = width_vel

    def transforms(self, controls: np.ndarray) -> np.ndarray:
        """Per-frame unit dual quaternions (F, 8) of the controls."""
        return sdlb.blend(self.basis, controls)

    def value(self, flat: np.ndarray) -> float:
        rot, trans = dualquat.to_rotation_translation(self.transforms(flat.reshape(-1, 8)))
        e_pos, e_vel, _, _ = self.energy(rot, trans, self.width_pos, self.width_vel, gradient=False)
        return e_pos + e_vel

    def __call__(self, flat: np.ndarray) -> tuple[float, np.ndarray]:
        controls = flat.reshape(-1, 8)
        dq = self.transforms(controls)
        rot, trans = dualquat.to_rotation_translation(dq)
        e_pos, e_vel, g_rot, g_trans = self.energy(rot, trans, self.width_pos, self.width_vel)
        grad = sdlb.blend_vjp(self.basis, controls, dualquat.rotation_translation_vjp(dq, g_rot, g_trans))
        return e_pos + e_vel, grad.ravel()
