"""The preview processor: a `*.preview.usdc` layer of displayColor heat maps for usdview.

Colours show each vertex's dynamics offset along its normal (green out, red in, grey
zero) on a symmetric range in mm, the way the papers show results; muting the layer
brings back the plain surface. It reads the take below the preview role: the strongest
result under it (synthesized, else quasistatic).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from facedyn.errors import UsageError
from facedyn.processors.base import LayerOutput, Parameter, Plan, Processor, Reads, Request, Writes, single_input
from facedyn.progress import Progress


class PreviewProcessor(Processor):
    name = "preview"
    version = "1"
    summary = "write a displayColor heat-map layer of the dynamics offsets for usdview"
    reads = Reads("take", help="the take root (reads the strongest result below any preview layer)")
    writes = Writes("layer", role="preview", help="the preview layer to write (*.preview.usdc)")
    parameters = (
        Parameter("range_mm", float, 0.0, "colour range in mm, symmetric (0: the 99.5th percentile of the take)", minimum=0.0),
    )

    def prepare(self, request: Request) -> Plan:
        from facedyn.usd.errors import TakeError
        from facedyn.usd.take import read_take_below

        path = single_input(request)
        if not request.output.name.endswith(".preview.usdc"):
            raise UsageError(f"{request.output}: name preview layers *.preview.usdc so tools can tell them apart")
        perf, source = read_take_below(path, self.writes.role, frames=request.frames)
        if perf.offsets is None:
            raise TakeError(f"{path}: {source.mesh_path} has no dynamics offsets to preview (run remove or synthesize first)")
        description = {"take": str(path), "frames": perf.frame_count, "mesh": source.mesh_path}
        return Plan(description, (perf, source, request.params["range_mm"]))

    def run(self, plan: Plan, progress: Progress) -> LayerOutput:
        from facedyn.preview.heatmap import offset_heat
        from facedyn.usd import schema
        from facedyn.usd.layers import LayerContent

        perf, source, range_mm = plan.state
        colours, signed, used_range_mm = offset_heat(perf.points, perf.offsets, perf.topology.triangles(), range_mm or None)
        layer = LayerContent(frames=perf.frames, mesh_path=source.mesh_path,
                             skull_path=source.skull_path or str(Path(source.mesh_path).parent),
                             display_color=colours, face=schema.FaceAttributes(role=None))
        summary = {"range_mm": used_range_mm, "peak_normal_offset_mm": round(float(np.abs(signed).max()), 2)}
        return LayerOutput(layer=layer, timing=source.timing, inputs=list(source.inputs), summary=summary)
