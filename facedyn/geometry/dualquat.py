"""Unit dual quaternions on arrays, batched over leading axes.

A dual quaternion is an 8-vector: the real quaternion r (w, x, y, z) then the dual part d,
both scalar-first like facedyn.geometry.quaternion. A unit dual quaternion (|r| = 1,
r . d = 0) is the rigid transform ``p -> R(r) p + t`` with ``d = 0.5 (0, t) r``. Blending
dual quaternions linearly and renormalizing (DLB, papers/001) stays rigid, which is why
the stabilizer parameterizes skull motion with them.
"""
from __future__ import annotations

import numpy as np

from facedyn.geometry import quaternion


def _check(dq: np.ndarray, name: str = "dq") -> np.ndarray:
    dq = np.asarray(dq, dtype=np.float64)
    if dq.shape[-1:] != (8,):
        raise ValueError(f"{name} must have a last axis of 8 (real then dual quaternion), got {dq.shape}")
    return dq


def identity(shape: tuple[int, ...] = ()) -> np.ndarray:
    dq = np.zeros(shape + (8,))
    dq[..., 0] = 1.0
    return dq


def multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dual quaternion product a * b (apply b, then a)."""
    a = _check(a, "a")
    b = _check(b, "b")
    real = quaternion.multiply(a[..., :4], b[..., :4])
    dual = quaternion.multiply(a[..., :4], b[..., 4:]) + quaternion.multiply(a[..., 4:], b[..., :4])
    return np.concatenate([real, dual], axis=-1)


def conjugate(dq: np.ndarray) -> np.ndarray:
    """Quaternion conjugate of both parts: the inverse of a unit dual quaternion."""
    dq = _check(dq)
    return dq * np.array([1.0, -1.0, -1.0, -1.0, 1.0, -1.0, -1.0, -1.0])


def normalize(dq: np.ndarray) -> np.ndarray:
    """Divide by the dual norm |r| + eps (r.d)/|r|: gives |r| = 1 and r . d = 0.

    Scaling both parts by 1/|r| alone would leave r . d != 0, which is not a rigid motion.
    """
    dq = _check(dq)
    real, dual = dq[..., :4], dq[..., 4:]
    n = np.linalg.norm(real, axis=-1, keepdims=True)
    if np.any(n == 0):
        raise ValueError("cannot normalize a dual quaternion with a zero real part")
    r = real / n
    d = (dual - r * np.sum(r * dual, axis=-1, keepdims=True)) / n
    return np.concatenate([r, d], axis=-1)


def normalize_vjp(dq: np.ndarray, grad: np.ndarray) -> np.ndarray:
    """Gradient with respect to dq of a scalar whose gradient with respect to normalize(dq) is grad."""
    dq = _check(dq)
    grad = _check(grad, "grad")
    real, dual = dq[..., :4], dq[..., 4:]
    n = np.linalg.norm(real, axis=-1, keepdims=True)
    r = real / n
    rd = np.sum(r * dual, axis=-1, keepdims=True)
    d = (dual - r * rd) / n
    gr, gd = grad[..., :4], grad[..., 4:]
    r_gd = np.sum(r * gd, axis=-1, keepdims=True)
    g_dual = (gd - r * r_gd) / n
    gr_total = gr - (rd * gd + dual * r_gd) / n
    g_real = (gr_total - r * np.sum(r * gr_total, axis=-1, keepdims=True)) / n
    g_real = g_real - r * np.sum(gd * d, axis=-1, keepdims=True) / n
    return np.concatenate([g_real, g_dual], axis=-1)


def from_translate_orient(translate: np.ndarray, orient: np.ndarray) -> np.ndarray:
    """The unit dual quaternion of ``p -> R(orient) p + translate``."""
    translate = np.asarray(translate, dtype=np.float64)
    orient = np.asarray(orient, dtype=np.float64)
    if translate.shape[-1:] != (3,) or orient.shape[-1:] != (4,):
        raise ValueError(f"translate must be (..., 3) and orient (..., 4), got {translate.shape} and {orient.shape}")
    r = quaternion.normalize(orient)
    t = np.concatenate([np.zeros(translate.shape[:-1] + (1,)), translate], axis=-1)
    r, t = np.broadcast_arrays(r, t)
    return np.concatenate([r, 0.5 * quaternion.multiply(t, r)], axis=-1)


def to_rotation_translation(dq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R (..., 3, 3), t (..., 3)) of a unit dual quaternion, without renormalizing.

    Uses the quadratic form of R(r) valid for unit r; its vector-Jacobian product is
    rotation_translation_vjp.
    """
    dq = _check(dq)
    w, x, y, z = np.moveaxis(dq[..., :4], -1, 0)
    dw, dv = dq[..., 4], dq[..., 5:]
    v = dq[..., 1:4]
    rot = np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )
    trans = 2.0 * (w[..., None] * dv - dw[..., None] * v + np.cross(v, dv))
    return rot, trans


def rotation_translation_vjp(dq: np.ndarray, grad_rotation: np.ndarray, grad_translate: np.ndarray) -> np.ndarray:
    """Gradient with respect to a unit dq, given gradients with respect to its (R, t).

    R is taken in the form (w^2 - |v|^2) I + 2 v v^T + 2 w [v]x, which equals
    to_rotation_translation's on unit quaternions; the radial part this adds is removed by
    normalize_vjp, so composing the two gives the true gradient.
    """
    dq = _check(dq)
    g = np.asarray(grad_rotation, dtype=np.float64)
    gt = np.asarray(grad_translate, dtype=np.float64)
    w, v = dq[..., :1], dq[..., 1:4]
    dw, dv = dq[..., 4:5], dq[..., 5:]
    tr = (g[..., 0, 0] + g[..., 1, 1] + g[..., 2, 2])[..., None]
    axial = np.stack([g[..., 2, 1] - g[..., 1, 2], g[..., 0, 2] - g[..., 2, 0], g[..., 1, 0] - g[..., 0, 1]], -1)
    sym_v = np.einsum("...ij,...j->...i", g + np.swapaxes(g, -1, -2), v)
    g_w = 2.0 * w * tr + 2.0 * np.sum(v * axial, axis=-1, keepdims=True) + 2.0 * np.sum(gt * dv, axis=-1, keepdims=True)
    g_v = -2.0 * tr * v + 2.0 * sym_v + 2.0 * w * axial - 2.0 * dw * gt + 2.0 * np.cross(dv, gt)
    g_dw = -2.0 * np.sum(gt * v, axis=-1, keepdims=True)
    g_dv = 2.0 * (w * gt + np.cross(gt, v))
    return np.concatenate([g_w, g_v, g_dw, g_dv], axis=-1)


def to_translate_orient(dq: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(translate (..., 3), orient (..., 4) wxyz) of a dual quaternion (normalized first)."""
    dq = normalize(dq)
    _, trans = to_rotation_translation(dq)
    return trans, dq[..., :4].copy()


def to_matrix(dq: np.ndarray) -> np.ndarray:
    """(..., 8) -> (..., 4, 4) homogeneous matrices acting on column vectors."""
    rot, trans = to_rotation_translation(normalize(dq))
    m = np.zeros(rot.shape[:-2] + (4, 4))
    m[..., :3, :3] = rot
    m[..., :3, 3] = trans
    m[..., 3, 3] = 1.0
    return m


def from_matrix(m: np.ndarray) -> np.ndarray:
    """(..., 4, 4) rigid homogeneous matrices -> unit dual quaternions (real part w >= 0)."""
    m = np.asarray(m, dtype=np.float64)
    if m.shape[-2:] != (4, 4):
        raise ValueError(f"matrices must be (..., 4, 4), got {m.shape}")
    return from_translate_orient(m[..., :3, 3], quaternion.from_matrix(m[..., :3, :3]))


def transform_points(dq: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply dq (..., 8) to point sets (..., N, 3): one transform per leading index."""
    dq = _check(dq)
    points = np.asarray(points, dtype=np.float64)
    if points.shape[-1:] != (3,) or points.ndim < 2:
        raise ValueError(f"points must be (..., N, 3), got {points.shape}")
    rot, trans = to_rotation_translation(normalize(dq))
    return np.einsum("...ij,...nj->...ni", rot, points) + trans[..., None, :]


def make_continuous(dq: np.ndarray) -> np.ndarray:
    """Flip signs along axis 0 so consecutive real parts lie in the same hemisphere."""
    dq = _check(dq)
    dots = np.sum(dq[1:, :4] * dq[:-1, :4], axis=-1)
    flips = np.concatenate([[1.0], np.cumprod(np.where(dots < 0, -1.0, 1.0))])
    return dq * flips.reshape((-1,) + (1,) * (dq.ndim - 1))
