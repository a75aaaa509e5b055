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
    """psi(u) elementwise for u = |x| / w (the formula as written in the paper)."""
    u = np.abs(np.asarray(u, dtype=np.float64))
    return np.where(u < 0.5, 2.0 * u * u, np.where(u < 1.0, 1.0 - 2.0 * (1.0 - u) ** 2, 1.0))


def _row_dots(a: np.ndarray, b: np.ndarray) -> float:
    """sum(a * b) as per-row dot products (BLAS, in the arrays' dtype) added in float64.

    One float32 dot over millions of values loses ~1e-5 relative accuracy, too much for
    line searches; rows of a few thousand keep ~1e-7 at the same speed.
    """
    ra = a.reshape(a.shape[0], -1)
    rb = b.reshape(b.shape[0], -1)
    return float(np.matmul(ra[:, None, :], rb[:, :, None]).sum(dtype=np.float64))


def fade_terms(
    x: np.ndarray,
    width: float,
    out: np.ndarray,
    scratch: np.ndarray,
    weights: np.ndarray | None = None,
    tmp: np.ndarray | None = None,
) -> float:
    """Energy sum_{f, c, n} weights_n psi(|x| / width) (float64), and ``out = 2 h - c``.

    x: (F, 3, N); weights (N,) run along the last axis (None: all 1). The gradient of the
    energy with respect to x is ``4 / width^2 * weights * out``; it is left unscaled so
    that callers fold the scale and the weights into later passes. out, scratch (and tmp,
    needed with weights) are preallocated arrays of x's shape and dtype; scratch may be x
    itself (x is then overwritten); out and tmp may not alias x.
    """
    if not width > 0:
        raise ValueError(f"penalty width must be positive, got {width}")
    if weights is not None and tmp is None:
        raise ValueError("weighted fade_terms needs a tmp buffer")
    c, h = scratch, out
    np.clip(x, -width, width, out=c)
    np.clip(c, -0.5 * width, 0.5 * width, out=h)

    def sum_squares(a: np.ndarray) -> float:
        if weights is None:
            return _row_dots(a, a)
        np.multiply(a, weights, out=tmp)
        return _row_dots(tmp, a)

    sum_c2 = sum_squares(c)
    np.subtract(c, h, out=c)  # e = c - h
    sum_e2 = sum_squares(c)
    np.subtract(h, c, out=h)  # h - e = 2 h - c
    return float(2.0 * sum_c2 - 4.0 * sum_e2) / (width * width)
