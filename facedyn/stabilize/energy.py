"""The mode-pursuit energy of one take (or chunk) and its gradient, on float32 arrays.

E = sum_f,v,c w_v [psi(|S - X_rest|_c / w_pos) + psi(|dS/dt|_c / w_vel)] with
S_f = R_f X_f + t_f. The gradient is returned with respect to the per-frame (R_f, t_f);
facedyn.stabilize.objective carries it to the spline controls. Every step is a whole-array
pass (BLAS matmul, sparse stencil, clip), float32 for the big arrays and float64 for sums.

Float32 and rigid transforms: rounding R_f to float32 moves every point of a frame
coherently by ~1e-7 of its radius, and the fade penalty is so sharply curved at small
widths that this shifts the gradient by percents and stalls L-BFGS. So the points are
stored already moved by a base transform B_f (``rebase``, once per stage, in float64),
and each evaluation applies only the small change R_f B_f^-1, as ``X' + (dR - I) X' + dt``
whose float32 rounding is ~1e-7 of the change, not of the point.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from facedyn.stabilize.penalty import fade_terms


def check_problem(points: np.ndarray, rest: np.ndarray, velocity: sp.spmatrix, weights: np.ndarray | None):
    """Validate an evaluator's inputs (shared by the NumPy and OpenCL evaluators)."""
    points = np.asarray(points)
    if points.ndim != 3 or points.shape[1] != 3:
        raise ValueError(f"points must be (frames, 3, N), got {points.shape}")
    f, _, n = points.shape
    if np.shape(rest) != (3, n):
        raise ValueError(f"rest must be (3, {n}), got {np.shape(rest)}")
    if velocity.shape != (f, f):
        raise ValueError(f"velocity operator must be ({f}, {f}), got {velocity.shape}")
    if weights is not None and np.shape(weights) != (n,):
        raise ValueError(f"weights must be ({n},), got {np.shape(weights)}")
    return points


class Rebase:
    """The base transforms B_f = (R_b, t_b) of an evaluator and the maps to and from them."""

    def __init__(self, frames: int):
        self.rot = np.broadcast_to(np.eye(3), (frames, 3, 3)).copy()
        self.trans = np.zeros((frames, 3))

    def apply(self, points: np.ndarray, rot: np.ndarray, trans: np.ndarray, out: np.ndarray, block: int = 256) -> None:
        """out = B points with B = (rot, trans), computed in float64 a block of frames at a time."""
        self.rot, self.trans = np.array(rot, dtype=np.float64), np.array(trans, dtype=np.float64)
        for start in range(0, len(points), block):
            sl = slice(start, start + block)
            out[sl] = np.matmul(self.rot[sl], points[sl].astype(np.float64)) + self.trans[sl, :, None]

    def relative(self, rot: np.ndarray, trans: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(dR - I, dt) with R X + t = dR (B X) + dt: dR = R R_b^T, dt = t - dR t_b."""
        d_rot = np.matmul(rot, np.swapaxes(self.rot, 1, 2))
        d_trans = trans - np.einsum("fij,fj->fi", d_rot, self.trans)
        return d_rot - np.eye(3), d_trans

    def absolute_gradient(self, g_rel: np.ndarray, g_trans: np.ndarray) -> np.ndarray:
        """dE/dR from G' = sum g X'^T and sum g, with X' = R_b X + t_b: (G' - g t_b^T) R_b."""
        return np.matmul(g_rel - g_trans[:, :, None] * self.trans[:, None, :], self.rot)


class NumpyEnergy:
    """Energy evaluator bound to one problem's arrays; reuses its buffers between calls.

    points: (F, 3, N) tracked vertices (coordinate-major so that every frame is a small
    GEMM); rest: (3, N); velocity: sparse (F, F) d/dt operator; weights: (N,) or None.
    dtype float32 is the fast solver's; float64 gives a reference value of the energy.
    """

    def __init__(
        self,
        points: np.ndarray,
        rest: np.ndarray,
        velocity: sp.spmatrix,
        weights: np.ndarray | None = None,
        dtype=np.float32,
    ):
        points = check_problem(points, rest, velocity, weights)
        f, _, n = points.shape
        self.dtype = np.dtype(dtype)
        self.frames, self.count = f, n
        self.points = points
        self.base = Rebase(f)
        self.homogeneous = np.empty((f, 4, n), dtype)  # [B X; 1]: one GEMM gives the change
        self.homogeneous[:, :3] = points
        self.homogeneous[:, 3] = 1.0
        self.rest = np.ascontiguousarray(rest, dtype=dtype)
        self.velocity = sp.csr_matrix(velocity, dtype=dtype)
        self.velocity_t = self.velocity.T.tocsr()
        self.weights = None if weights is None else np.asarray(weights, dtype)
        self._stabilized = np.empty((f, 3, n), dtype)
        self._residual = np.empty((f, 3, n), dtype)
        self._grad = np.empty((f, 3, n), dtype)
        self._vel_grad = np.empty((f, 3, n), dtype)

    def rebase(self, rot: np.ndarray, trans: np.ndarray) -> None:
        """Store the points moved by (rot, trans), near which the next evaluations lie."""
        self.base.apply(self.points, rot, trans, self.homogeneous[:, :3])

    def stabilized(self, rot: np.ndarray, trans: np.ndarray) -> np.ndarray:
        """S_f = R_f X_f + t_f as (F, 3, N) (a view of an internal buffer)."""
        d_rot, d_trans = self.base.relative(rot, trans)
        rt = np.concatenate([d_rot, d_trans[:, :, None]], axis=2).astype(self.dtype)
        s = np.matmul(rt, self.homogeneous, out=self._stabilized)
        s += self.homogeneous[:, :3]
        return s

    def __call__(self, rot: np.ndarray, trans: np.ndarray, width_pos: float, width_vel: float, gradient: bool = True):
        """(position energy, velocity energy, dE/dR (F,3,3), dE/dt (F,3)); gradients None when not asked."""
        s = self.stabilized(rot, trans)
        np.subtract(s, self.rest, out=self._residual)
        e_pos = fade_terms(self._residual, width_pos, self._grad, self._residual, self.weights, self._vel_grad)
        if self.frames > 1:
            vel = (self.velocity @ s.reshape(self.frames, -1)).reshape(s.shape)
            e_vel = fade_terms(vel, width_vel, self._vel_grad, vel, self.weights, self._residual)
        else:
            e_vel = 0.0
        if not gradient:
            return e_pos, e_vel, None, None
        # dE/dS = 4/wp^2 W g_pos + 4/wv^2 W D^T g_vel, scaled and weighted once at the end
        g = self._grad
        if self.frames > 1:
            scaled_t = self.velocity_t * self.dtype.type((width_pos / width_vel) ** 2)
            g += (scaled_t @ self._vel_grad.reshape(self.frames, -1)).reshape(g.shape)
        if self.weights is not None:
            g *= self.weights
        grt = np.einsum("fin,fjn->fij", g, self.homogeneous).astype(np.float64) * (4.0 / width_pos**2)
        return e_pos, e_vel, self.base.absolute_gradient(grt[:, :, :3], grt[:, :, 3]), grt[:, :, 3]
