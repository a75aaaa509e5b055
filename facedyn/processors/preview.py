"""The preview processor: a `*.preview.usdc` layer of displayColor heat maps for usdview.

Colours show each vertex's dynamics offset along its normal (green out, red in, grey
zero) on a symmetric range in mm, the way the papers show results; muting the layer
brings back the plain surface.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from facedyn.errors import UsageError
from facedyn.processors.base import Parameter, Processor, Request, Result
from facedyn.progress import Progress


class PreviewProcessor(Processor):
    name = "preview"
    version = "1"
    summary = "write a displayColor heat-map layer of the dynamics offsets for usdview"
    parameters = (
        Parameter("range_mm", float, 0.0, "colour range in mm, symmetric (0: the 99.5th percentile of the take)"),
    )

    def check(self, request: Request) -> dict:
        if len(request.inputs) != 1:
            raise UsageError("preview takes one TAKE")
        if not request.output.name.endswith(".preview.usdc"):
            raise UsageError(f"{request.output}: name preview layers *.preview.usdc so tools can tell them apart")
        perf, source = _read(request)
        return {"take": str(request.inputs[0]), "frames": perf.frame_count, "mesh": source.mesh_path}

    def run(self, request: Request, progress: Progress) -> Result:
        from facedyn.preview.heatmap import offset_heat
        from facedyn.usd import schema
        from facedyn.usd.layers import LayerContent

        self.check(request)
        perf, source = _read(request)
        colours, signed, range_mm = offset_heat(perf.points, perf.offsets, perf.topology.triangles(),
                                                request.params["range_mm"] or None)
        layer = LayerContent(frames=perf.frames, mesh_path=source.mesh_path, skull_path=source.skull_path or str(Path(source.mesh_path).parent),
                             display_color=colours, face=schema.FaceAttributes(role=None))
        summary = {"range (mm)": range_mm, "peak |normal offset| (mm)": round(float(np.abs(signed).max()), 2)}
        return Result(layer=layer, timing=source.timing, inputs=list(source.layer_identifiers), summary=summary)


def _read(request: Request):
    from facedyn.usd.errors import TakeError
    from facedyn.usd.take import read_take

    perf, source = read_take(request.inputs[0], frames=request.frames)
    if perf.offsets is None:
        raise TakeError(f"{request.inputs[0]}: {source.mesh_path} has no dynamics offsets to preview (run remove or synthesize first)")
    return perf, source
