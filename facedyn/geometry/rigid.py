"""Rigid alignment of point sets with known correspondences, batched over frames.

Every function maps ``source`` onto ``target``: ``target ~ R @ source + t``. Leading axes
are batch axes (frames), solved together with one batched SVD, never a Python loop.
These are the stabilization baselines of papers/001 (three-point, Procrustes, robust ICP)
and the mode-pursuit initializers.
"""
from __future__ import annotations

import numpy as np

LOSSES = ("geman-mcclure", "huber", "trim")


def _pair(source: np.ndarray, target: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    source = np.asarray(source, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    if source.ndim < 2 or source.shape[-1] != 3:
        raise ValueError(f"source must be (..., N, 3), got {source.shape}")
    if target.ndim < 2 or target.shape[-1] != 3:
        raise ValueError(f"target must be (..., N, 3), got {target.shape}")
    if source.shape[-2] != target.shape[-2]:
        raise ValueError(f"source has {source.shape[-2]} points, target {target.shape[-2]}")
    return source, target


def _point_weights(weights: np.ndarray | None, batch: tuple[int, ...], n: int) -> np.ndarray:
    if weights is None:
        return np.ones(batch + (n,))
    w = np.asarray(weights, dtype=np.float64)
    try:
        w = np.broadcast_to(w, batch + (n,))
    except ValueError:
        raise ValueError(f"weights of shape {w.shape} do not broadcast to (..., N) = {batch + (n,)}") from None
    if np.any(w < 0):
        raise ValueError("weights must be non-negative")
    if np.any(w.sum(axis=-1) <= 0):
        raise ValueError("every frame needs a positive total weight")
    return w


def kabsch(source: np.ndarray, target: np.ndarray, weights: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least-squares rigid transform (no scale, no reflection).

    source, target: (..., N, 3); weights: broadcastable to (..., N).
    Returns R (..., 3, 3) and t (..., 3) minimizing sum_n w_n |R s_n + t - x_n|^2.
    """
    source, target = _pair(source, target)
    batch = np.broadcast_shapes(source.shape[:-2], target.shape[:-2])
    w = _point_weights(weights, batch, source.shape[-2])
    wsum = w.sum(axis=-1, keepdims=True)
    cs = np.einsum("...n,...ni->...i", w, source) / wsum
    ct = np.einsum("...n,...ni->...i", w, target) / wsum
    # H = sum w (s - cs)(x - ct)^T, expanded so that no centred copies are made
    h = np.einsum("...n,...ni,...nj->...ij", w, source, target) - wsum[..., None] * cs[..., :, None] * ct[..., None, :]
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(np.swapaxes(vt, -1, -2) @ np.swapaxes(u, -1, -2)))
    d = np.where(d == 0, 1.0, d)
    fix = np.ones(batch + (3,))
    fix[..., 2] = d
    rot = np.swapaxes(vt, -1, -2) @ (fix[..., :, None] * np.swapaxes(u, -1, -2))
    trans = ct - np.einsum("...ij,...j->...i", rot, cs)
    return rot, trans


def _weighted_median(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    order = np.argsort(values, axis=-1)
    v = np.take_along_axis(values, order, axis=-1)
    cw = np.cumsum(np.take_along_axis(weights, order, axis=-1), axis=-1)
    idx = np.argmax(cw >= 0.5 * cw[..., -1:], axis=-1)
    return np.take_along_axis(v, idx[..., None], axis=-1)[..., 0]


def robust_icp(
    source: np.ndarray,
    target: np.ndarray,
    weights: np.ndarray | None = None,
    loss: str = "geman-mcclure",
    scale: float | None = None,
    iterations: int = 10,
    trim: float = 0.5,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Iteratively reweighted Kabsch: rigid fit that ignores points that deform.

    Correspondences are known (tracked meshes), so "ICP" here is only its reweighting
    loop: fit, measure residuals r, set per-point weights from a robust loss, refit.
    - ``geman-mcclure``: rho = r^2 / (r^2 + s^2), IRLS weight (s^2 / (r^2 + s^2))^2;
    - ``huber``: weight min(1, 1.345 s / r);
    - ``trim``: weight 1 for the ``trim`` fraction of smallest residuals, else 0.
    ``scale`` s (length units) defaults to 1.4826 x the weighted median residual of each
    frame (MAD), recomputed every iteration, never below 1e-9 of the target's extent.
    Returns R (..., 3, 3), t (..., 3) and the final robust weights (..., N) (without the
    given prior weights, which multiply them).
    """
    if loss not in LOSSES:
        raise ValueError(f"loss must be one of {LOSSES}, got {loss!r}")
    if iterations < 1:
        raise ValueError(f"iterations must be >= 1, got {iterations}")
    if not 0.0 < trim <= 1.0:
        raise ValueError(f"trim must be in (0, 1], got {trim}")
    source, target = _pair(source, target)
    batch = np.broadcast_shapes(source.shape[:-2], target.shape[:-2])
    prior = _point_weights(weights, batch, source.shape[-2])
    floor = 1e-9 * max(float(np.ptp(target)), 1e-300)
    robust = np.ones(batch + (source.shape[-2],))
    rot, trans = kabsch(source, target, prior)
    for _ in range(iterations):
        resid = np.linalg.norm(np.einsum("...ij,...nj->...ni", rot, source) + trans[..., None, :] - target, axis=-1)
        if loss == "trim":
            keep = max(1, int(round(trim * resid.shape[-1])))
            cut = np.partition(np.where(prior > 0, resid, np.inf), keep - 1, axis=-1)[..., keep - 1 : keep]
            robust = (resid <= cut).astype(np.float64)
        else:
            s = np.full(batch, float(scale)) if scale is not None else 1.4826 * _weighted_median(resid, prior)
            s = np.maximum(s, floor)[..., None]
            if loss == "geman-mcclure":
                robust = (s * s / (resid * resid + s * s)) ** 2
            else:
                robust = np.minimum(1.0, 1.345 * s / np.maximum(resid, 1e-300))
        rot, trans = kabsch(source, target, prior * robust)
    return rot, trans, robust


def three_point_frame(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal frame (columns) and origin (centroid) of point triples (..., 3, 3).

    x runs from the first point to the second, z is normal to the triangle, y = z x x.
    """
    p = np.asarray(points, dtype=np.float64)
    if p.shape[-2:] != (3, 3):
        raise ValueError(f"three-point frames need (..., 3, 3) point triples, got {p.shape}")
    e1 = p[..., 1, :] - p[..., 0, :]
    e3 = np.cross(e1, p[..., 2, :] - p[..., 0, :])
    n1 = np.linalg.norm(e1, axis=-1, keepdims=True)
    n3 = np.linalg.norm(e3, axis=-1, keepdims=True)
    if np.any(n1 == 0) or np.any(n3 <= 1e-12 * n1 * n1):
        raise ValueError("the three points are coincident or collinear in some frame")
    e1 = e1 / n1
    e3 = e3 / n3
    e2 = np.cross(e3, e1)
    return np.stack([e1, e2, e3], axis=-1), p.mean(axis=-2)


def three_point(source: np.ndarray, target: np.ndarray, indices) -> tuple[np.ndarray, np.ndarray]:
    """Rigid transform that maps the frame of three chosen source vertices onto the target's.

    Exact when those three vertices are rigid; every other vertex is ignored.
    """
    source, target = _pair(source, target)
    idx = np.asarray(indices, dtype=np.int64)
    if idx.shape != (3,) or len(set(idx.tolist())) != 3:
        raise ValueError(f"three-point alignment needs 3 distinct vertex indices, got {indices!r}")
    n = source.shape[-2]
    if idx.min() < -n or idx.max() >= n:
        raise ValueError(f"three-point indices {idx.tolist()} out of range for {n} points")
    fs, os_ = three_point_frame(source[..., idx, :])
    ft, ot = three_point_frame(target[..., idx, :])
    rot = ft @ np.swapaxes(fs, -1, -2)
    trans = ot - np.einsum("...ij,...j->...i", rot, os_)
    return rot, trans
