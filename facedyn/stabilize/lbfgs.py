"""L-BFGS for a fixed number of iterations, with a strong-Wolfe line search.

Mode pursuit restarts L-BFGS at every stage and stops after a fixed iteration count
(papers/001), so every evaluation counts: the first trial step of a restart is scaled
by the previous stage's inverse-Hessian estimate (passed in by the caller), and the
line search (Nocedal & Wright, algorithms 3.5 and 3.6, cubic interpolation) accepts the
unit step whenever it meets the strong Wolfe conditions, which is most of the time.
The curvature condition keeps the stored (s, y) pairs informative on this C1-only
energy, where a plain Armijo backtracking search stalls on noisy, tiny steps.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

C1 = 1e-4  # sufficient decrease
C2 = 0.9  # curvature
MAX_EVALUATIONS = 6  # per line search: more means rounding noise, not curvature
FIRST_STEP = 1e-2  # largest coordinate change of a first step without a known scale
FTOL = 1e-8  # relative decrease below which an iteration counts as stalled
PATIENCE = 2  # consecutive stalled iterations that end the run


@dataclass
class LbfgsResult:
    x: np.ndarray
    fun: float
    evaluations: int
    iterations: int
    scale: float | None  # last s.y / y.y: the inverse-Hessian scale to start the next run with


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """a . b without BLAS: OpenBLAS threads dot products of >10k values, and on a busy
    machine waking those threads costs milliseconds per call."""
    return float(np.einsum("i,i->", a, b))


def _direction(g: np.ndarray, pairs: list, scale: float) -> np.ndarray:
    """-H g by the two-loop recursion, H0 = scale * I."""
    q = g.copy()
    alphas = []
    for s, y, rho in reversed(pairs):
        a = rho * _dot(s, q)
        q -= a * y
        alphas.append(a)
    r = scale * q
    for (s, y, rho), a in zip(pairs, reversed(alphas)):
        r += (a - rho * _dot(y, r)) * s
    return -r


def _cubic_minimum(a, fa, da, b, fb, db, lo, hi) -> float:
    """Minimizer of the cubic through (a, fa, da) and (b, fb, db), clipped to [lo, hi]."""
    d1 = da + db - 3.0 * (fa - fb) / (a - b)
    square = d1 * d1 - da * db
    if square < 0:
        return 0.5 * (lo + hi)
    d2 = np.sign(b - a) * np.sqrt(square)
    t = b - (b - a) * (db + d2 - d1) / (db - da + 2.0 * d2)
    return float(min(max(t, lo), hi)) if np.isfinite(t) else 0.5 * (lo + hi)


def _line_search(fun, x, f0, g0, d, alpha):
    """Strong-Wolfe step along d: ((alpha, f, g) or None, evaluations, converged).

    Out of evaluations without a Wolfe point means f is at its rounding floor along d
    (``converged``); the lowest point seen is returned if it decreased f.
    """
    slope0 = _dot(g0, d)
    evaluations = 0
    best = None

    def phi(step):
        nonlocal evaluations, best
        f, g = fun(x + step * d)
        evaluations += 1
        if f < f0 and (best is None or f < best[1]):
            best = (step, f, g)
        return f, g, _dot(g, d)

    def zoom(lo, hi):
        # lo = (step, f, slope) with sufficient decrease; hi brackets a Wolfe point with lo
        while evaluations < MAX_EVALUATIONS:
            width = hi[0] - lo[0]
            inner = sorted((lo[0] + 0.1 * width, hi[0] - 0.1 * width))
            step = _cubic_minimum(*lo, *hi, *inner)
            f, g, s = phi(step)
            if f > f0 + C1 * step * slope0 or f >= lo[1]:
                hi = (step, f, s)
            else:
                if abs(s) <= -C2 * slope0:
                    return step, f, g
                if s * width >= 0:
                    hi = lo
                lo = (step, f, s)
        return None

    prev = (0.0, f0, slope0)
    found = None
    while evaluations < MAX_EVALUATIONS:
        f, g, s = phi(alpha)
        if f > f0 + C1 * alpha * slope0 or (evaluations > 1 and f >= prev[1]):
            found = zoom(prev, (alpha, f, s))
            break
        if abs(s) <= -C2 * slope0:
            found = (alpha, f, g)
            break
        if s >= 0:
            found = zoom((alpha, f, s), prev)
            break
        prev, alpha = (alpha, f, s), _cubic_minimum(*prev, alpha, f, s, alpha * 1.01 + 1e-12, alpha * 10.0)
    if found is None:
        return best, evaluations, True
    return found, evaluations, False


def minimize(fun, x0: np.ndarray, iterations: int, scale: float | None = None, history: int | None = None):
    """Minimize fun(x) -> (f, grad) for ``iterations`` iterations.

    It stops earlier only when converged to the resolution of f (float32 energies are
    exact to ~1e-7, and further line searches would spend evaluations on rounding noise):
    when two line searches in a row, the second one after a restart of the quasi-Newton
    memory, run out of evaluations without a Wolfe point, or after PATIENCE consecutive
    iterations that each gained less than FTOL * |f|.
    """
    if iterations < 0:
        raise ValueError(f"iterations must be >= 0, got {iterations}")
    history = iterations if history is None else history
    x = np.array(x0, dtype=np.float64)
    f, g = fun(x)
    evaluations, done, stalled, exhausted = 1, 0, 0, False
    pairs: list = []
    while done < iterations:
        step_scale = FIRST_STEP / max(float(np.abs(g).max()), 1e-300) if scale is None else scale
        d = _direction(g, pairs, step_scale)
        if not _dot(g, d) < 0:
            pairs.clear()
            d = -step_scale * g
        if not _dot(g, d) < 0:
            break  # zero gradient
        found, count, converged = _line_search(fun, x, f, g, d, 1.0)
        evaluations += count
        failed = converged or found is None
        # at f's rounding floor twice in a row, or even along the scaled gradient: stop;
        # the first time, restart the quasi-Newton memory
        stop = failed and (exhausted or not pairs)
        exhausted = failed
        if failed:
            pairs.clear()
        if found is not None:
            alpha, f_new, g_new = found
            s, y = alpha * d, g_new - g
            sy = _dot(s, y)
            if sy > 1e-10 and not failed:
                pairs.append((s, y, 1.0 / sy))
                if len(pairs) > history:
                    pairs.pop(0)
                scale = sy / _dot(y, y)
            stalled = stalled + 1 if f - f_new < FTOL * abs(f) else 0
            x, f, g = x + s, f_new, g_new
            done += 1
        if stop or stalled >= PATIENCE:
            break
    return LbfgsResult(x, float(f), evaluations, done, scale)
