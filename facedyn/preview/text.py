"""Text labels for review images, drawn by OpenImageIO with its bundled font.

The OpenImageIO wheel ships the Droid fonts, so labels render the same on a render node
without system fonts as on a workstation; naming the font keeps them from changing with
whatever fonts a machine happens to have installed.
"""
from __future__ import annotations

import numpy as np
import OpenImageIO as oiio

FONT = "DroidSans"


def text_size(text: str, size: int) -> tuple[int, int]:
    """(width, height) in pixels of `text` at font `size` (height from ascent to descent)."""
    if not text:
        return 0, 0
    roi = oiio.ImageBufAlgo.text_size(text, int(size), FONT)
    if not roi.defined:
        raise RuntimeError(f"OpenImageIO cannot measure text with font {FONT!r}: {oiio.geterror()}")
    return roi.xend - roi.xbegin, roi.yend - roi.ybegin


def draw_text(
    image: np.ndarray,
    text: str,
    x: int,
    y: int,
    size: int = 14,
    color: tuple[float, float, float] = (0.92, 0.92, 0.92),
    align_x: str = "left",
    align_y: str = "top",
) -> np.ndarray:
    """Draw `text` anchored at pixel (x, y) into a (H, W, 3) uint8 `image`, in place.

    `align_x` is "left", "center" or "right" and `align_y` "top", "center", "bottom" or
    "baseline": which point of the text's box sits at (x, y). Only the pixels around the
    text go through OpenImageIO, so labelling a large sheet stays cheap. Returns `image`.
    """
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise ValueError(f"image must be (H, W, 3) uint8, got {image.shape} {image.dtype}")
    if align_x not in ("left", "center", "right") or align_y not in ("top", "center", "bottom", "baseline"):
        raise ValueError(f"bad alignment {align_x!r}, {align_y!r}")
    if not text:
        return image
    w, h = text_size(text, size)
    reach_x, reach_y = w + size, h + size
    x0, x1 = max(x - reach_x, 0), min(x + reach_x, image.shape[1])
    y0, y1 = max(y - reach_y, 0), min(y + reach_y, image.shape[0])
    if x0 >= x1 or y0 >= y1:
        return image
    buf = oiio.ImageBuf(np.ascontiguousarray(image[y0:y1, x0:x1]))
    ok = oiio.ImageBufAlgo.render_text(
        buf, int(x - x0), int(y - y0), text, int(size), FONT, tuple(float(c) for c in color), align_x, align_y
    )
    if not ok:
        raise RuntimeError(f"OpenImageIO could not draw text with font {FONT!r}: {buf.geterror()}")
    image[y0:y1, x0:x1] = buf.get_pixels(oiio.UINT8)
    return image
