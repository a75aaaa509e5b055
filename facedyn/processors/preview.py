"""The preview processor: a `*.preview.usdc` layer of displayColor heat maps for usdview.

Colours show each vertex's dynamics offset along its normal (green out, red in, grey
zero) on a symmetric range in mm, the way the papers show results; muting the layer
brings back the plain surface. It reads the take below the preview role: the strongest
result under it (synthesized, else quasistatic). It streams in chunks; the automatic colour
range is taken on an even sample of at most 2,048 frames (every frame of a shorter take).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from facedyn.errors import UsageError
from facedyn.performance import PREVIEW
from facedyn.processors.base import LayerOutput, Parameter, Plan, Processor, Reads, Request, Writes, single_input
from facedyn.processors.model_steps import model_windows
from facedyn.progress import Progress


class PreviewProcessor(Processor):
    name = "preview"
    version = "1"
    summary = "write a displayColor heat-map layer of the dynamics offsets for usdview"
    reads = Reads("take", help="the take root (reads the strongest result below any preview layer)")
    writes = Writes("layer", role=PREVIEW, help="the preview layer to write (*.preview.usdc)")
    parameters = (
        Parameter("range_mm", float, 0.0, "colour range in mm, symmetric (0: the 99.5th percentile of the take)", minimum=0.0),
    )

    def prepare(self, request: Request) -> Plan:
        from facedyn.usd.errors import TakeError
        from facedyn.usd.frames import TakeFrames

        path = single_input(request)
        if not request.output.name.endswith(".preview.usdc"):
            raise UsageError(f"{request.output}: name preview layers *.preview.usdc so tools can tell them apart")
        reader = TakeFrames(path, self.writes.role, frames=request.frames)
        if reader.head.offsets is None:
            raise TakeError(f"{path}: {reader.source.mesh_path} has no dynamics offsets to preview (run remove or synthesize first)")
        description = {"take": str(path), "frames": reader.frame_count, "mesh": reader.source.mesh_path}
        return Plan(description, (reader, request.params["range_mm"]))

    def run(self, plan: Plan, progress: Progress) -> LayerOutput:
        from facedyn.preview.heatmap import offset_heat
        from facedyn.stabilize.rest import sample_frames
        from facedyn.usd import schema
        from facedyn.usd.layers import LayerContent

        reader, range_mm = plan.state
        source, triangles = reader.source, reader.head.topology.triangles()
        if not range_mm:
            sample = reader.read_frames(sample_frames(reader.frame_count))
            range_mm = offset_heat(sample.points, sample.offsets, triangles)[2]
        layer = LayerContent(frames=reader.time_codes, mesh_path=source.mesh_path,
                             skull_path=source.skull_path or str(Path(source.mesh_path).parent), face=schema.FaceAttributes(role=None))
        summary = {"range_mm": range_mm, "peak_normal_offset_mm": 0.0}

        def chunks():
            progress.start("preview", reader.frame_count)
            for window in model_windows(reader):
                colours, signed, _ = offset_heat(window.take.points, window.take.offsets, triangles, range_mm)
                peak = round(float(np.abs(signed).max()), 2)
                summary["peak_normal_offset_mm"] = max(summary["peak_normal_offset_mm"], peak)
                yield LayerContent(frames=window.take.frames, display_color=colours)
                progress.advance(window.stop - window.start)
            progress.finish()

        return LayerOutput(layer=layer, timing=source.timing, inputs=list(source.inputs), summary=summary, chunks=chunks())
