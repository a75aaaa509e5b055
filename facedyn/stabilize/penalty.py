"""The fade penalty of papers/001 (n = 2) on arrays.

psi(u) = 2 u^2 for u < 0.5, 1 - 2 (1 - u)^2 for 0.5 <= u < 1, 1 beyond, with u = |x| / w:
flat at 0, saturated beyond the width w (a smooth stand-in for the l0 "norm"), C1.
Written without branches as psi = (2 c^2 - 4 (c - h)^2) / w^2 with c = clip(x, -w, w) and
h = clip(x, -w/2, w/2), whose derivative is 4 (2 h - c) / w^2, so that the fast solver
needs only a few passes over the data.
"""
from __future__ import annotations

import numpy as np


def fade(u: np.ndarray) -> np.ndarray:
    """psi(u) elementwise for u = |x| / w >= 0 (the formula as written in the paper)."""
    u = np.abs(np.asarray(u, dtype=np.float64))
    return np.where(u < 0.5, 2.0 * u * u, np.where(u < 1.0, 1.0 - 2.0 * (1.0 - u) ** 2, 1.0))


def fade_sum_and_grad(x: np.ndarray, width: float, out: np.ndarray, scratch: np.ndarray) -> float:
    """sum psi(|x| / width) over all of x (float64); writes d/dx into ``out``.

    x is left unchanged; out and scratch are preallocated arrays of x's shape and dtype
    (out may not alias x). Sums are taken row by row in x's dtype, then in float64, which
    keeps float32 energies accurate enough for line searches.
    """
    if width <= 0:
        raise ValueError(f"penalty width must be positive, got {width}")
    c, h = scratch, out
    np.clip(x, -width, width, out=c)
    np.clip(x, -0.5 * width, 0.5 * width, out=h)
    rows_c = c.reshape(-1, c.shape[-1])
    sum_c2 = np.einsum("ij,ij->i", rows_c, rows_c).sum(dtype=np.float64)
    np.subtract(c, h, out=c)  # c - h
    sum_e2 = np.einsum("ij,ij->i", rows_c, rows_c).sum(dtype=np.float64)
    np.subtract(h, c, out=h)  # 2h - c = h - (c - h)
    np.multiply(h, 4.0 / (width * width), out=h)
    return (2.0 * sum_c2 - 4.0 * sum_e2) / (width * width)


def fade_weighted_sum_and_grad(
    x: np.ndarray, width: float, weights: np.ndarray, out: np.ndarray, scratch: np.ndarray
) -> float:
    """Like fade_sum_and_grad with per-vertex weights broadcast along x's last axis."""
    if width <= 0:
        raise ValueError(f"penalty width must be positive, got {width}")
    c, h = scratch, out
    np.clip(x, -width, width, out=c)
    np.clip(x, -0.5 * width, 0.5 * width, out=h)
    rows_c = c.reshape(-1, c.shape[-1])
    w = np.asarray(weights, dtype=np.float64)
    sum_c2 = np.einsum("ij,ij->j", rows_c, rows_c, dtype=np.float64) @ w
    np.subtract(c, h, out=c)
    sum_e2 = np.einsum("ij,ij->j", rows_c, rows_c, dtype=np.float64) @ w
    np.subtract(h, c, out=h)
    np.multiply(h, (4.0 / (width * width)) * weights.astype(x.dtype), out=h)
    return (2.0 * sum_c2 - 4.0 * sum_e2) / (width * width)
