"""Line charts on arrays (no plotting library): diagnostics plots written through OpenImageIO.

A chart is a panel of an (H, W, 3) uint8 image: a frame, x/y ranges, polylines drawn as
densely sampled points, and labels through facedyn.preview.text.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facedyn.preview.colormap import BACKGROUND
from facedyn.preview.text import draw_text

PALETTE = ((0.95, 0.55, 0.2), (0.35, 0.7, 0.95), (0.55, 0.85, 0.4), (0.9, 0.4, 0.6), (0.85, 0.85, 0.4), (0.7, 0.6, 0.95),
           (0.4, 0.9, 0.85), (0.95, 0.95, 0.95))
AXIS = (0.6, 0.6, 0.6)
MARGIN = 44


@dataclass
class Series:
    label: str
    x: np.ndarray
    y: np.ndarray


def blank(height: int, width: int) -> np.ndarray:
    """An (H, W, 3) uint8 image of the preview background."""
    image = np.empty((height, width, 3), np.uint8)
    image[:] = (np.asarray(BACKGROUND[:3]) * 255).astype(np.uint8)
    return image


def line_chart(image: np.ndarray, box: tuple[int, int, int, int], title: str, series: list[Series], x_label: str,
               x_range: tuple[float, float] | None = None, log_y: bool = False) -> np.ndarray:
    """Draw `series` into `box` = (x0, y0, x1, y1) pixels of `image`, in place, with a legend."""
    x0, y0, x1, y1 = box
    left, top, right, bottom = x0 + MARGIN, y0 + 28, x1 - 12, y1 - 30
    xs = np.concatenate([s.x for s in series])
    lo, hi = x_range or (float(xs.min()), float(xs.max()))
    values = [np.log10(np.maximum(s.y, 1e-6)) if log_y else np.asarray(s.y, np.float64) for s in series]
    ys = np.concatenate(values)
    y_lo, y_hi = float(ys.min()), float(ys.max())
    if y_hi <= y_lo:
        y_hi = y_lo + 1.0
    _rectangle(image, left, top, right, bottom, AXIS)
    for k, (s, v) in enumerate(zip(series, values)):
        keep = (s.x >= lo) & (s.x <= hi)
        px = left + (np.asarray(s.x)[keep] - lo) / max(hi - lo, 1e-12) * (right - left)
        py = bottom - (v[keep] - y_lo) / (y_hi - y_lo) * (bottom - top)
        _polyline(image, px, py, PALETTE[k % len(PALETTE)])
        draw_text(image, s.label, right - 6, top + 6 + 16 * k, 13, PALETTE[k % len(PALETTE)], align_x="right")
    draw_text(image, title, x0 + 8, y0 + 6, 15)
    draw_text(image, f"{lo:.3g}", left, bottom + 6, 12)
    draw_text(image, f"{hi:.3g} {x_label}", right, bottom + 6, 12, align_x="right")
    scale = "log10 " if log_y else ""
    draw_text(image, f"{scale}{y_hi:.3g}", x0 + 4, top, 11)
    draw_text(image, f"{scale}{y_lo:.3g}", x0 + 4, bottom, 11, align_y="bottom")
    return image


def _rectangle(image, left, top, right, bottom, color) -> None:
    rgb = (np.asarray(color) * 255).astype(np.uint8)
    image[top, left:right + 1] = rgb
    image[bottom, left:right + 1] = rgb
    image[top:bottom + 1, left] = rgb
    image[top:bottom + 1, right] = rgb


def _polyline(image: np.ndarray, px: np.ndarray, py: np.ndarray, color) -> None:
    """Segments between consecutive points, sampled every half pixel."""
    if len(px) == 0:
        return
    rgb = (np.asarray(color) * 255).astype(np.uint8)
    if len(px) == 1:
        xs, ys = px, py
    else:
        steps = np.maximum(np.ceil(2 * np.hypot(np.diff(px), np.diff(py))).astype(int), 1)
        t = np.concatenate([np.arange(n) / n for n in steps])
        start = np.repeat(np.arange(len(steps)), steps)
        xs = np.append(px[start] + t * (px[start + 1] - px[start]), px[-1])
        ys = np.append(py[start] + t * (py[start + 1] - py[start]), py[-1])
    xi = np.clip(np.round(xs).astype(int), 0, image.shape[1] - 1)
    yi = np.clip(np.round(ys).astype(int), 0, image.shape[0] - 1)
    image[yi, xi] = rgb
