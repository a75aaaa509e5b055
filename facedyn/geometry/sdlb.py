"""Spline dual-quaternion linear blending (SDLB, papers/001) and its gradient.

``r_f = normalize(sum_i B_i(x_f) q_i)``: a smooth curve of rigid transforms from a few
control dual quaternions q_i. q and -q are the same rigid motion, but blending them
cancels, so every control is first sign-aligned with its predecessor (antipodal
handling). The gradients are written out by hand so that the stabilizer's fast solver
needs no autodiff; tests check them against finite differences.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse import linalg as spla

from facedyn.geometry import dualquat


def _controls(controls: np.ndarray) -> np.ndarray:
    controls = np.asarray(controls, dtype=np.float64)
    if controls.ndim != 2 or controls.shape[1] != 8:
        raise ValueError(f"control dual quaternions must be (n, 8), got {controls.shape}")
    return controls


def align_signs(controls: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sign-align each control's real part with the previous (aligned) one.

    Returns the aligned controls and the (n,) signs applied, so that gradients can be
    mapped back: d/dq_i = sign_i * d/d(aligned q_i).
    """
    controls = _controls(controls)
    dots = np.sum(controls[1:, :4] * controls[:-1, :4], axis=-1)
    signs = np.concatenate([[1.0], np.cumprod(np.where(dots < 0, -1.0, 1.0))])
    return controls * signs[:, None], signs


def _check_basis(basis, controls: np.ndarray):
    if basis.ndim != 2 or basis.shape[1] != controls.shape[0]:
        raise ValueError(f"basis of shape {basis.shape} does not match {controls.shape[0]} controls")
    return basis


def blend_raw(basis, controls: np.ndarray) -> np.ndarray:
    """Unnormalized blend sum_i B_i q_i of sign-aligned controls: (frames, 8)."""
    controls = _controls(controls)
    aligned, _ = align_signs(controls)
    return np.asarray(_check_basis(basis, controls) @ aligned)


def blend(basis, controls: np.ndarray) -> np.ndarray:
    """SDLB: unit dual quaternions (frames, 8) from a (frames x controls) basis matrix."""
    return dualquat.normalize(blend_raw(basis, controls))


def blend_vjp(basis, controls: np.ndarray, grad: np.ndarray) -> np.ndarray:
    """Gradient (n, 8) with respect to the controls, given the gradient (frames, 8) with
    respect to the blended, normalized dual quaternions."""
    controls = _controls(controls)
    _, signs = align_signs(controls)
    raw = blend_raw(basis, controls)
    g_raw = dualquat.normalize_vjp(raw, grad)
    basis_t = basis.T if sp.issparse(basis) else np.asarray(basis).T
    return np.asarray(basis_t @ g_raw) * signs[:, None]


def transform_points_vjp(dq: np.ndarray, points: np.ndarray, grad_points: np.ndarray) -> np.ndarray:
    """Gradient (frames, 8) with respect to unit dq (frames, 8) of a scalar, given its
    gradient with respect to ``transform_points(dq, points)`` (frames, N, 3)."""
    points = np.asarray(points, dtype=np.float64)
    grad_points = np.asarray(grad_points, dtype=np.float64)
    if points.shape != grad_points.shape:
        raise ValueError(f"points {points.shape} and their gradient {grad_points.shape} differ in shape")
    g_rot = np.einsum("...ni,...nj->...ij", grad_points, points)
    g_trans = grad_points.sum(axis=-2)
    return dualquat.rotation_translation_vjp(dq, g_rot, g_trans)


def fit_controls(basis, dq: np.ndarray, smoothing: float = 1e-8) -> np.ndarray:
    """Least-squares controls whose blend reproduces per-frame dual quaternions dq.

    dq is sign-made-continuous first; the fit is linear, so the blend equals dq up to the
    renormalization SDLB applies. A tiny second-difference penalty on the controls
    (``smoothing`` relative to the basis's Gram matrix) keeps the fit well posed where
    few frames fall under a control's support.
    """
    dq = dualquat.make_continuous(np.asarray(dq, dtype=np.float64))
    if dq.ndim != 2 or dq.shape[0] != basis.shape[0]:
        raise ValueError(f"{dq.shape} dual quaternions for a basis of {basis.shape[0]} frames")
    b = sp.csr_matrix(basis)
    n = b.shape[1]
    normal = (b.T @ b).tocsr()
    penalty = sp.identity(n)
    if n >= 3:
        second = sp.diags([1.0, -2.0, 1.0], [0, 1, 2], shape=(n - 2, n))
        penalty = second.T @ second + 1e-6 * penalty
    normal = normal + smoothing * normal.diagonal().mean() * penalty
    return np.asarray(spla.spsolve(normal.tocsc(), np.asarray(b.T @ dq))).reshape(-1, 8)
