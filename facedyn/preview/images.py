"""Image files through OpenImageIO, written atomically, and labelled contact sheets.

Review frames and uv maps are picked up by viewers, compositors and farm jobs while a
run is still going, so a file only ever appears complete: it is written under a hidden
temporary name in its destination folder and renamed into place (a rename within one
folder is atomic).
"""
from __future__ import annotations

import os
import uuid
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from facedyn.preview import text
from facedyn.preview.colormap import BACKGROUND

_FORMATS = {
    np.dtype(np.uint8): oiio.UINT8,
    np.dtype(np.uint16): oiio.UINT16,
    np.dtype(np.float16): oiio.HALF,
    np.dtype(np.float32): oiio.FLOAT,
    np.dtype(np.float64): oiio.FLOAT,
}


def write_image(
    path: str | os.PathLike,
    pixels: np.ndarray,
    attributes: dict | None = None,
    channel_names: tuple[str, ...] | None = None,
    file_format: str | None = None,
) -> Path:
    """Write (H, W) or (H, W, C) `pixels` to `path` atomically; the format follows the suffix.

    `attributes` become header metadata (int, float or str values). `file_format` is
    the pixel type stored in the file ("half", "float", "uint8", ...), by default the
    array's own. Returns the path written.
    """
    path = Path(path)
    folder = path.parent
    if not folder.is_dir():
        raise ValueError(f"cannot write {path}: folder {folder} does not exist")
    if not os.access(folder, os.W_OK):
        raise ValueError(f"cannot write {path}: folder {folder} is not writable")
    arr = np.asarray(pixels)
    if arr.ndim == 2:
        arr = arr[:, :, None]
    if arr.ndim != 3 or not 1 <= arr.shape[2] <= 4 or arr.shape[0] == 0 or arr.shape[1] == 0:
        raise ValueError(f"pixels must be (H, W) or (H, W, 1..4), got {np.shape(pixels)}")
    if arr.dtype not in _FORMATS:
        raise ValueError(f"pixels must be uint8, uint16 or float, got {arr.dtype}")
    if arr.dtype == np.float64:
        arr = arr.astype(np.float32)
    height, width, channels = arr.shape
    spec = oiio.ImageSpec(width, height, channels, oiio.TypeDesc(file_format) if file_format else _FORMATS[arr.dtype])
    if channel_names is not None:
        if len(channel_names) != channels:
            raise ValueError(f"{len(channel_names)} channel names for {channels} channels")
        spec.channelnames = tuple(channel_names)
    for name, value in (attributes or {}).items():
        if isinstance(value, np.generic):
            value = value.item()
        if not isinstance(value, (int, float, str)) or isinstance(value, bool):
            raise ValueError(f"attribute {name!r} must be an int, float or str, got {type(value).__name__}")
        spec.attribute(name, value)

    tmp = folder / f".{path.name}.{uuid.uuid4().hex[:12]}.tmp{path.suffix}"
    out = oiio.ImageOutput.create(str(tmp))
    if out is None:
        oiio.geterror()  # taken so that it is not reported again at exit; the message below says it
        raise ValueError(f"cannot write {path}: OpenImageIO has no writer for {path.suffix!r} files")
    try:
        written = out.open(str(tmp), spec) and out.write_image(np.ascontiguousarray(arr))
        error = out.geterror()
        closed = out.close()
        if not (written and closed):
            raise OSError(f"cannot write {path}: {error or out.geterror()}")
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def read_image(path: str | os.PathLike) -> tuple[np.ndarray, dict]:
    """(pixels (H, W, C) in the file's type, half read as float32; header attributes)."""
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise ValueError(f"cannot read {path}: {oiio.geterror()}")
    try:
        spec = inp.spec()
        stored = spec.format
        pixels = inp.read_image(oiio.FLOAT if stored.basetype == oiio.HALF else stored)
        if pixels is None:
            raise OSError(f"cannot read {path}: {inp.geterror()}")
    finally:
        inp.close()
    attributes = {p.name: p.value for p in spec.extra_attribs}
    attributes["channelnames"] = tuple(spec.channelnames)
    return pixels.reshape(spec.height, spec.width, spec.nchannels), attributes


def contact_sheet(
    rows: list[tuple[str, list[np.ndarray]]],
    frame_labels: list,
    legend: np.ndarray | None = None,
    font_size: int = 16,
    gap: int = 8,
    background: tuple[float, float, float] = BACKGROUND,
) -> np.ndarray:
    """One uint8 (H, W, 3) image comparing sequences frame by frame.

    Each row is (label, images) — e.g. captured / quasistatic / synthesized — with one
    image per entry of `frame_labels` (column headers, usually frame numbers). All
    images are (h, w, 3) uint8 of one size. The `legend` image, if any, goes at the right.
    """
    if not rows:
        raise ValueError("contact_sheet needs at least one row")
    columns = len(frame_labels)
    if columns == 0:
        raise ValueError("contact_sheet needs at least one frame label")
    cell = None
    for label, images in rows:
        if len(images) != columns:
            raise ValueError(f"row {label!r} has {len(images)} images for {columns} frame labels")
        for image in images:
            if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
                raise ValueError(f"row {label!r}: images must be (h, w, 3) uint8, got {image.shape} {image.dtype}")
            cell = cell or image.shape[:2]
            if image.shape[:2] != cell:
                raise ValueError(f"row {label!r}: image of {image.shape[:2]} among images of {cell}")
    if legend is not None and (legend.ndim != 3 or legend.shape[2] != 3 or legend.dtype != np.uint8):
        raise ValueError(f"legend must be (h, w, 3) uint8, got {legend.shape} {legend.dtype}")

    ch, cw = cell
    labels = [str(f) for f in frame_labels]
    line = text.text_size("0Ag", font_size)[1]
    label_w = max(text.text_size(label, font_size)[0] for label, _ in rows)
    left = gap + label_w + gap
    top = gap + line + gap
    grid_w = columns * cw + (columns - 1) * gap
    grid_h = len(rows) * ch + (len(rows) - 1) * gap
    legend_w = 0 if legend is None else gap + legend.shape[1]
    height = top + max(grid_h, 0 if legend is None else legend.shape[0]) + gap
    width = left + grid_w + legend_w + gap

    sheet = np.empty((height, width, 3), dtype=np.uint8)
    sheet[:] = np.round(np.clip(background, 0, 1) * 255).astype(np.uint8)
    for c, label in enumerate(labels):
        text.draw_text(sheet, label, left + c * (cw + gap) + cw // 2, gap, font_size, align_x="center")
    for r, (label, images) in enumerate(rows):
        y = top + r * (ch + gap)
        text.draw_text(sheet, label, gap, y + ch // 2, font_size, align_y="center")
        for c, image in enumerate(images):
            x = left + c * (cw + gap)
            sheet[y : y + ch, x : x + cw] = image
    if legend is not None:
        x = left + grid_w + gap
        sheet[top : top + legend.shape[0], x : x + legend.shape[1]] = legend
    return sheet
