"""Review pictures of a take, as the papers show them: heat-mapped faces side by side.

A contact sheet has one row per version of a performance (captured / quasistatic /
synthesized) and one column per chosen frame; every face is coloured by its dynamics
offset along the normal (green out, red in, grey none) on one shared range in mm.
"""
from __future__ import annotations

import numpy as np

from facedyn.preview.colormap import legend
from facedyn.preview.heatmap import offset_heat, symmetric_range_mm
from facedyn.preview.images import contact_sheet
from facedyn.preview.raster import Renderer, frame_camera


def review_sheet(
    rows: list[tuple[str, np.ndarray, np.ndarray | None]],
    triangles: np.ndarray,
    frames: np.ndarray,
    columns: list[int],
    size: int = 256,
    yaw: float = 0.0,
    range_mm: float | None = None,
) -> tuple[np.ndarray, float]:
    """(sheet image (H, W, 3) uint8, colour range in mm).

    rows: (label, skull-space points (F, N, 3), offsets (F, N, 3) or None for no colour);
    columns: frame indices to show, labelled with `frames[index]`.
    """
    if not rows:
        raise ValueError("review_sheet needs at least one row")
    everything = np.concatenate([points[columns] for _, points, _ in rows])
    camera = frame_camera(everything, yaw=yaw, width=size, height=size)
    renderer = Renderer(triangles, everything.shape[1], camera)
    heats = {}
    for label, points, offsets in rows:
        if offsets is not None:
            heats[label] = offset_heat(points[columns], offsets[columns], triangles, range_mm)
    if range_mm is None:
        signed = [signed for _, signed, _ in heats.values()]
        range_mm = symmetric_range_mm(np.concatenate(signed)) if signed else 1.0
        heats = {label: offset_heat(points[columns], offsets[columns], triangles, range_mm)
                 for label, points, offsets in rows if offsets is not None}
    images = []
    for label, points, offsets in rows:
        colours = heats[label][0] if label in heats else [None] * len(columns)
        images.append((label, [renderer.render(points[c], colours[i]) for i, c in enumerate(columns)]))
    sheet = contact_sheet(images, [f"frame {frames[c]:g}" for c in columns], legend=legend(range_mm, height=size))
    return sheet, range_mm
