"""Clamped B-splines: the basis matrix by Cox-de Boor's recursion, and midpoint refinement.

The stabilizer's skull motion is a B-spline of control dual quaternions (papers/001):
its values at all frames are ``basis(knots, x) @ controls``, a sparse (frames x controls)
product, and its coarse-to-fine continuation inserts a knot at the midpoint of every
span, which changes the control polygon but not the curve.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp


def clamped_uniform_knots(spans: int, start: float = 0.0, end: float = 1.0, degree: int = 3) -> np.ndarray:
    """Knots of a clamped spline with ``spans`` equal spans on [start, end]: spans + degree controls."""
    if spans < 1:
        raise ValueError(f"a spline needs at least one span, got {spans}")
    if not end > start:
        raise ValueError(f"the spline domain must have end > start, got [{start}, {end}]")
    inner = np.linspace(start, end, spans + 1)
    return np.concatenate([np.full(degree, float(start)), inner, np.full(degree, float(end))])


def control_count(knots: np.ndarray, degree: int = 3) -> int:
    return len(knots) - degree - 1


def _check_knots(knots: np.ndarray, degree: int) -> np.ndarray:
    knots = np.asarray(knots, dtype=np.float64)
    if degree < 0:
        raise ValueError(f"degree must be >= 0, got {degree}")
    if knots.ndim != 1 or len(knots) < 2 * (degree + 1):
        raise ValueError(f"a degree-{degree} spline needs at least {2 * (degree + 1)} knots, got {knots.shape}")
    if np.any(np.diff(knots) < 0):
        raise ValueError("knots must be non-decreasing")
    return knots


def _span(knots: np.ndarray, x: np.ndarray, degree: int) -> np.ndarray:
    """Index i with knots[i] <= x < knots[i+1]; the domain's right end belongs to the last span."""
    lo, hi = knots[degree], knots[-degree - 1]
    if np.any(x < lo) or np.any(x > hi):
        raise ValueError(f"parameters must lie in the spline domain [{lo}, {hi}]")
    span = np.searchsorted(knots, x, side="right") - 1
    return np.minimum(span, len(knots) - degree - 2)


def _local_basis(knots: np.ndarray, x: np.ndarray, span: np.ndarray, degree: int) -> np.ndarray:
    """The degree+1 non-zero basis values at each x (Cox-de Boor's triangle, vectorized over x)."""
    values = np.zeros((len(x), degree + 1))
    values[:, 0] = 1.0
    left = np.zeros((len(x), degree + 1))
    right = np.zeros((len(x), degree + 1))
    for j in range(1, degree + 1):
        left[:, j] = x - knots[span + 1 - j]
        right[:, j] = knots[span + j] - x
        saved = np.zeros(len(x))
        for r in range(j):
            denom = right[:, r + 1] + left[:, j - r]
            temp = np.divide(values[:, r], denom, out=np.zeros(len(x)), where=denom != 0)
            values[:, r] = saved + right[:, r + 1] * temp
            saved = left[:, j - r] * temp
        values[:, j] = saved
    return values


def basis(knots: np.ndarray, x: np.ndarray, degree: int = 3, derivative: int = 0) -> sp.csr_matrix:
    """Sparse (len(x), controls) matrix of B_i,p(x) (derivative 0) or dB_i,p/dx (derivative 1).

    Rows sum to 1 (partition of unity) for derivative 0 and to 0 for derivative 1.
    """
    knots = _check_knots(knots, degree)
    if derivative not in (0, 1):
        raise ValueError(f"derivative must be 0 or 1, got {derivative}")
    x = np.atleast_1d(np.asarray(x, dtype=np.float64))
    if x.ndim != 1:
        raise ValueError(f"parameters must be a 1-D array, got {x.shape}")
    span = _span(knots, x, degree)
    if derivative == 0:
        values = _local_basis(knots, x, span, degree)
    else:
        if degree == 0:
            values = np.zeros((len(x), 1))
        else:
            # dB_i,p = p (B_i,p-1 / (t_i+p - t_i) - B_i+1,p-1 / (t_i+p+1 - t_i+1))
            low = _local_basis(knots, x, span, degree - 1)  # B_{span-p+1 .. span, p-1}
            i = span[:, None] - degree + np.arange(degree + 1)[None, :]
            padded = np.concatenate([np.zeros((len(x), 1)), low, np.zeros((len(x), 1))], axis=1)
            a = np.take(knots, i + degree) - np.take(knots, i)
            b = np.take(knots, i + degree + 1) - np.take(knots, i + 1)
            term_a = np.divide(padded[:, :-1], a, out=np.zeros_like(a), where=a != 0)
            term_b = np.divide(padded[:, 1:], b, out=np.zeros_like(b), where=b != 0)
            values = degree * (term_a - term_b)
    cols = span[:, None] - degree + np.arange(degree + 1)[None, :]
    rows = np.repeat(np.arange(len(x)), degree + 1)
    return sp.csr_matrix((values.ravel(), (rows, cols.ravel())), shape=(len(x), control_count(knots, degree)))


def insert_knot(knots: np.ndarray, controls: np.ndarray, u: float, degree: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Boehm's insertion of one knot u: same curve, one more control (rows of controls)."""
    knots = _check_knots(knots, degree)
    controls = np.asarray(controls, dtype=np.float64)
    if controls.shape[0] != control_count(knots, degree):
        raise ValueError(f"{len(knots)} knots need {control_count(knots, degree)} controls, got {controls.shape[0]}")
    k = int(_span(knots, np.array([u]), degree)[0])
    i = np.arange(k - degree + 1, k + 1)
    alpha = (u - knots[i]) / (knots[i + degree] - knots[i])
    alpha = alpha.reshape((-1,) + (1,) * (controls.ndim - 1))
    blended = alpha * controls[i] + (1.0 - alpha) * controls[i - 1]
    new_controls = np.concatenate([controls[: k - degree + 1], blended, controls[k:]], axis=0)
    return np.insert(knots, k + 1, u), new_controls


def refine_midpoints(knots: np.ndarray, controls: np.ndarray, degree: int = 3) -> tuple[np.ndarray, np.ndarray]:
    """Insert a knot at the midpoint of every non-empty span (Boehm): the curve is unchanged."""
    knots = _check_knots(knots, degree)
    distinct = np.unique(knots[degree : len(knots) - degree])
    for u in 0.5 * (distinct[:-1] + distinct[1:]):
        knots, controls = insert_knot(knots, controls, float(u), degree)
    return knots, controls


def evaluate(knots: np.ndarray, controls: np.ndarray, x: np.ndarray, degree: int = 3) -> np.ndarray:
    """Curve values sum_i B_i(x) c_i, controls (n, ...) -> (len(x), ...)."""
    controls = np.asarray(controls, dtype=np.float64)
    flat = controls.reshape(controls.shape[0], -1)
    return np.asarray(basis(knots, x, degree) @ flat).reshape((-1,) + controls.shape[1:])
