"""Review images and uv offset maps, on arrays and through OpenImageIO (no pxr).

raster: headless NumPy triangle rasterizer and cameras; normals: vertex normals;
colormap: the signed-offset colour map and its legend; text: labels; images: atomic
image files and contact sheets; uvmaps: per-frame UDIM EXR offset maps.
"""
from facedyn.lazy_exports import lazy_exports

_PUBLIC = {
    "offset_heat": "heatmap",
    "write_image": "images",
    "Series": "plot", "line_chart": "plot",
    "review_sheet": "review",
    "UVBaker": "uvmaps", "write_offset_maps": "uvmaps",
}

__all__, __getattr__ = lazy_exports(__name__, _PUBLIC)
