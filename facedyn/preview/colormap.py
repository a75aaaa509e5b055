"""A diverging colour map for signed per-vertex offsets, in millimetres.

Dynamics offsets are reviewed as "does the skin bulge out or sink in": the offset's
component along the vertex normal, green toward the viewer (outward, positive), red away
(inward, negative), grey at zero, on a symmetric range [-r, r] so that equal magnitudes
look equally strong on both sides.
"""
from __future__ import annotations

import numpy as np

from facedyn.preview import text

BACKGROUND = (0.12, 0.12, 0.12)  # behind renders, legends and contact sheets alike
ZERO = np.array([0.62, 0.62, 0.62])
POSITIVE = np.array([0.10, 0.78, 0.22])
NEGATIVE = np.array([0.88, 0.14, 0.10])


def normal_component_mm(offsets: np.ndarray, normals: np.ndarray, mm_per_unit: float = 10.0) -> np.ndarray:
    """Signed offset along the vertex normal, in mm: (offset . normal) * mm_per_unit.

    `offsets` (..., N, 3) in mesh units (cm by default, hence 10 mm per unit); `normals`
    (N, 3) or (..., N, 3) unit vertex normals. Returns (..., N).
    """
    off = np.asarray(offsets, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    if off.ndim < 2 or off.shape[-1] != 3:
        raise ValueError(f"offsets must be (..., N, 3), got {off.shape}")
    if nrm.shape[-2:] != off.shape[-2:]:
        raise ValueError(f"normals {nrm.shape} do not match offsets {off.shape}")
    return (np.einsum("...j,...j->...", off, nrm) * mm_per_unit).astype(np.float32)


def diverging(values_mm: np.ndarray, range_mm: float) -> np.ndarray:
    """RGB in [0, 1], shape (..., 3): grey at 0, fully green at +range_mm, red at -range_mm.

    Values beyond the range saturate at the end colours.
    """
    if not range_mm > 0:
        raise ValueError(f"range_mm must be positive, got {range_mm}")
    t = np.clip(np.asarray(values_mm, dtype=np.float64) / range_mm, -1.0, 1.0)[..., None]
    end = np.where(t >= 0, POSITIVE, NEGATIVE)
    return (ZERO + np.abs(t) * (end - ZERO)).astype(np.float32)


def legend(
    range_mm: float,
    height: int = 256,
    ticks: int = 5,
    font_size: int = 14,
    background: tuple[float, float, float] = BACKGROUND,
) -> np.ndarray:
    """A vertical colour bar with tick labels in mm: (height, width, 3) uint8, +r at the top."""
    if not range_mm > 0:
        raise ValueError(f"range_mm must be positive, got {range_mm}")
    if ticks < 2 or height < 4 * font_size:
        raise ValueError(f"legend needs at least 2 ticks and height >= {4 * font_size}, got {ticks}, {height}")
    values = np.linspace(range_mm, -range_mm, ticks)
    values[np.abs(values) < 1e-9 * range_mm] = 0.0
    labels = [f"{v:+.3g} mm" if v else "0 mm" for v in values]
    pad, bar_w = font_size // 2 + 2, max(font_size, 12)
    label_w = max(text.text_size(s, font_size)[0] for s in labels)
    width = pad + bar_w + pad + label_w + pad
    image = np.empty((height, width, 3), dtype=np.uint8)
    image[:] = np.round(np.clip(background, 0, 1) * 255).astype(np.uint8)
    top, bottom = pad + font_size // 2, height - pad - font_size // 2
    rows = np.arange(top, bottom)
    colours = diverging(np.interp(rows, [top, bottom - 1], [range_mm, -range_mm]), range_mm)
    image[top:bottom, pad : pad + bar_w] = np.round(colours * 255).astype(np.uint8)[:, None, :]
    for value, label in zip(values, labels):
        y = int(round(np.interp(value, [-range_mm, range_mm], [bottom - 1, top])))
        image[y, pad + bar_w : pad + bar_w + pad // 2] = 230
        text.draw_text(image, label, pad + bar_w + pad, y, font_size, align_y="center")
    return image
