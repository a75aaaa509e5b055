"""The remove processor: subtract the secondary dynamics that network F predicts.

Or that an actor's linear response predicts from the skull alone (a .response file from
`train-synthesis --response linear`, facedyn.dynamics.response): `--model` takes either, or
a blend file (`usdfacedyn calibrate`'s `removal.blend`), which removes the mean of its
members' dynamics or weighs them per frequency band as calibrate chose on the actor's session
(facedyn.dynamics.bands); `--blend MODEL` removes the mean of two files (F's and the actor's response,
whose errors are partly independent); `usdfacedyn evaluate --session --removal M --blend N`
scores the mean on the actor's session before a take is touched. A synthesis network H is
never a removal.

Reads the stabilized take (the layers below the quasistatic role) and writes the
quasistatic layer: points = the quasistatic skin in skull space, and the removed dynamics
as `primvars:facedyn:dynamicsOffset` (captured - quasistatic). F's features are skull
landmark motion in the skull frame, so the take must be stabilized.

The take streams through in chunks, each read with the frames of context the model's
windows reach, so the result equals the whole take's and memory is bounded by a chunk
(facedyn.processors.model_steps, which the other model steps share).
"""
from __future__ import annotations

from pathlib import Path

from facedyn.performance import BACKENDS, QUASISTATIC
from facedyn.processors.base import INFERENCE_DEVICE, LayerOutput, Parameter, Plan, Processor, Reads, Request, Writes
from facedyn.processors.model_steps import OffsetStats, model_inputs, model_windows, removal_blend, removal_of, take_reader
from facedyn.progress import Progress


class RemoveProcessor(Processor):
    name = "remove"
    version = "1"
    summary = "remove secondary dynamics with a trained removal model (network F) or an actor's linear response"
    reads = Reads("take", help="the take root (reads the stabilized take below any quasistatic layer)")
    writes = Writes("layer", role=QUASISTATIC, help="the quasistatic layer to write (.usdc)")
    parameters = (
        Parameter("model", Path, help="the removal model file (from train-removal), an actor's linear response "
                  "(.response, train-synthesis --response linear), a blend of them (calibrate's removal.blend), or `default`: "
                  "the shipped person-independent removal model, for an actor with neither rig nor session", metavar="MODEL"),
        Parameter("blend", Path, None, "a second removal model or linear response: remove the mean of the two models' dynamics",
                  metavar="MODEL"),
        Parameter("backend", str, "auto", "feature and Laplacian kernels", BACKENDS),
        INFERENCE_DEVICE,
    )

    def prepare(self, request: Request) -> Plan:
        params = request.params
        reader = take_reader(request, self.writes.role)
        removals, weights = removal_blend(params["model"], params["blend"], reader.head, reader.fps, request.inputs[0])
        models = [model for _, model in removals]
        description = {"take": str(request.inputs[0]), "frames": reader.frame_count, "model": str(params["model"]),
                       "blend": str(params["blend"] or ""), "samples": int(len(models[0].face.samples)),
                       **{f"face_{key}": models[0].info[key] for key in ("rest", "facing") if key in models[0].info}}  # a per-take setup's
        if not weights.is_mean():
            description["bands"] = weights.to_json()
        return Plan(description, (reader, models, weights, params))

    def run(self, plan: Plan, progress: Progress) -> LayerOutput:
        from facedyn.usd import schema
        from facedyn.usd.layers import LayerContent

        reader, models, weights, params = plan.state
        source = reader.source
        layer = LayerContent(frames=reader.time_codes, mesh_path=source.mesh_path, skull_path=source.skull_path,
                             face=schema.FaceAttributes(role=self.writes.role, skin_samples=models[0].face.samples))
        stats = OffsetStats("removed")

        def chunks():
            progress.start("remove dynamics", reader.frame_count)
            for window in model_windows(reader, *models, reach=weights.reach(reader.fps)):
                removed = [removal_of(window.take.points, *window.take.skull(), reader.fps, model, params["backend"], params["device"])
                           for model in models]
                quasistatic, offsets = weights.combine(removed, reader.fps)
                yield LayerContent(frames=reader.time_codes[window.start:window.stop], points=quasistatic[window.inner],
                                   offsets=stats.add(offsets[window.inner]))
                progress.advance(window.stop - window.start)
            progress.finish()

        paths = [params["model"]] + ([params["blend"]] if params["blend"] is not None else [])
        return LayerOutput(layer=layer, timing=source.timing, inputs=model_inputs(source, *paths),
                           summary=stats.summary, chunks=chunks())


