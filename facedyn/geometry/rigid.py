"""Rigid alignment of point sets with known correspondences, batched over frames.

Every function maps ``source`` onto ``target``: ``target ~ R @ source + t``. Leading axes
are batch axes (frames), solved together with one batched SVD, never a Python loop.
These are the stabilization baselines of papers/001 (three-point, Procrustes, robust ICP)
and the mode-pursuit initializers.
"""
from __future__ import annotations

import numpy as np

LOSSES = ("geman-mcclure", "huber", "trim")
MEDIAN_SAMPLES = 256  # residuals per frame that the robust scale (MAD) is taken from


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
    return _kabsch(source, target, _point_weights(weights, batch, source.shape[-2]))


def _kabsch(source: np.ndarray, target: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Kabsch on (..., N, 3) arrays in float64."""
    wsum = w.sum(axis=-1, keepdims=True)
    cs = np.matmul(w[..., None, :], source)[..., 0, :] / wsum
    ct = np.matmul(w[..., None, :], target)[..., 0, :] / wsum
    h = np.matmul(np.swapaxes(source * w[..., None], -1, -2), target)
    rot = _rotation(h - wsum[..., None] * cs[..., :, None] * ct[..., None, :])
    return rot, ct - np.matmul(rot, cs[..., None])[..., 0]


def _kabsch_columns(src: np.ndarray, tgt: np.ndarray, tgt_columns: np.ndarray, w: np.ndarray):
    """Kabsch on centred float32 data, source as columns (..., 3, N) (one GEMM per frame);
    the target comes in both layouts, (..., N, 3) and (..., 3, N)."""
    wsum = w.sum(axis=-1)
    cs = np.matmul(src, w[..., :, None])[..., 0] / wsum[..., None]
    ct = np.matmul(tgt_columns, w[..., :, None])[..., 0] / wsum[..., None]
    h = np.matmul(src * w[..., None, :], tgt) - wsum[..., None, None] * cs[..., :, None] * ct[..., None, :]
    rot = _rotation(h)
    return rot, ct - np.matmul(rot, cs[..., None].astype(np.float64))[..., 0]


def _rotation(h: np.ndarray) -> np.ndarray:
    """The proper rotation maximizing tr(R H) for cross-covariances H (..., 3, 3)."""
    u, _, vt = np.linalg.svd(h.astype(np.float64))
    v, ut = np.swapaxes(vt, -1, -2), np.swapaxes(u, -1, -2)
    fix = np.ones(h.shape[:-1])
    fix[..., 2] = np.where(np.linalg.det(v @ ut) < 0, -1.0, 1.0)
    return v @ (fix[..., :, None] * ut)


def apply(rot: np.ndarray, trans: np.ndarray, points: np.ndarray) -> np.ndarray:
    """R @ p + t for point sets (..., N, 3) and transforms (..., 3, 3), (..., 3)."""
    return np.matmul(points, np.swapaxes(rot, -1, -2)) + trans[..., None, :]


def _weighted_median(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Median along the last axis, weighted; a plain (faster) median when weights are a
    0/1 mask shared by all leading indices."""
    mask = weights.reshape(-1, weights.shape[-1])[0]
    if np.all((mask == 0) | (mask == 1)) and np.all(weights == mask):
        return np.median(values[..., mask > 0], axis=-1)
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
    frame (MAD, from about MEDIAN_SAMPLES evenly strided points), recomputed every
    iteration, never below 1e-9 of the target's extent.
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
    # reweight in float32 on centred, coordinate-major copies (fast GEMMs, half the
    # memory traffic, no cancellation), then fit once more in float64
    src = np.ascontiguousarray(np.swapaxes(source - source.mean(axis=-2, keepdims=True), -1, -2), dtype=np.float32)
    tgt = (target - target.mean(axis=-2, keepdims=True)).astype(np.float32)
    tgt_columns = np.ascontiguousarray(np.swapaxes(tgt, -1, -2))
    floor = 1e-9 * max(float(np.ptp(tgt)), 1e-30)
    prior32 = prior.astype(np.float32)
    stride = max(1, source.shape[-2] // MEDIAN_SAMPLES)
    robust = np.ones(batch + (source.shape[-2],), dtype=np.float32)
    rot, trans = _kabsch_columns(src, tgt, tgt_columns, prior32)
    for _ in range(iterations):
        d = np.matmul(rot.astype(np.float32), src) + trans.astype(np.float32)[..., :, None] - tgt_columns
        r2 = np.einsum("...cn,...cn->...n", d, d)
        if loss == "trim":
            keep = max(1, int(round(trim * r2.shape[-1])))
            cut = np.partition(np.where(prior > 0, r2, np.inf), keep - 1, axis=-1)[..., keep - 1 : keep]
            robust = (r2 <= cut).astype(np.float32)
        else:
            if scale is None:
                s = 1.4826 * np.sqrt(_weighted_median(r2[..., ::stride], prior[..., ::stride]))
            else:
                s = np.full(batch, float(scale))
            s2 = (np.maximum(s, floor) ** 2)[..., None].astype(np.float32)
            if loss == "geman-mcclure":
                robust = (s2 / (r2 + s2)) ** 2
            else:
                robust = np.minimum(1.0, 1.345 * np.sqrt(s2 / np.maximum(r2, 1e-30))).astype(np.float32)
        rot, trans = _kabsch_columns(src, tgt, tgt_columns, prior32 * robust)
    robust = robust.astype(np.float64)
    rot, trans = _kabsch(source, target, prior * robust)  # the final fit in float64
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
    trans = ot - np.matmul(rot, os_[..., None])[..., 0]
    return rot, trans
