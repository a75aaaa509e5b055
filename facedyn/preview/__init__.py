"""Review images and uv offset maps, on arrays and through OpenImageIO (no pxr).

raster: headless NumPy triangle rasterizer and cameras; normals: vertex normals;
colormap: the signed-offset colour map and its legend; text: labels; images: atomic
image files and contact sheets; uvmaps: per-frame UDIM EXR offset maps.
"""
