"""The remove processor: subtract the secondary dynamics that network F predicts.

Writes the quasistatic layer: points = the quasistatic skin in skull space, and the
removed dynamics as `primvars:facedyn:dynamicsOffset` (captured - quasistatic). The take
must be stabilized, since F's features are velocities in the skull frame.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from facedyn.errors import UsageError
from facedyn.processors.base import Parameter, Processor, Request, Result
from facedyn.progress import Progress


class RemoveProcessor(Processor):
    name = "remove"
    version = "1"
    summary = "remove secondary dynamics with a trained removal model (network F)"
    parameters = (
        Parameter("model", str, "", "the removal model file (from train-removal)"),
        Parameter("backend", str, "auto", "feature and Laplacian kernels: auto, opencl, numpy", ("auto", "opencl", "numpy")),
        Parameter("device", str, "auto", "torch device for the network: auto, cpu, cuda"),
    )

    def check(self, request: Request) -> dict:
        perf, source, model = _inputs(request)
        return {"take": str(request.inputs[0]), "frames": perf.frame_count, "model": request.params["model"],
                "samples": int(len(model.face.samples))}

    def run(self, request: Request, progress: Progress) -> Result:
        from facedyn.dynamics.removal import remove_dynamics
        from facedyn.usd import schema
        from facedyn.usd.layers import LayerContent

        perf, source, model = _inputs(request)
        translate, orient = perf.skull()
        progress.start("remove dynamics", 1)
        quasistatic, offsets = remove_dynamics(perf.points, translate, orient, perf.fps, model,
                                               backend=request.params["backend"], device=request.params["device"])
        progress.finish()
        layer = LayerContent(
            frames=perf.frames, mesh_path=source.mesh_path, skull_path=source.skull_path, points=quasistatic, offsets=offsets,
            face=schema.FaceAttributes(role="quasistatic", skin_samples=model.face.samples),
        )
        magnitude = np.linalg.norm(offsets, axis=-1)
        summary = {"peak removed offset (mm)": round(float(magnitude.max()) * 10, 3),
                   "RMS removed offset (mm)": round(float(np.sqrt(np.mean(magnitude**2))) * 10, 3)}
        inputs = list(source.layer_identifiers) + [str(Path(request.params["model"]).resolve())]
        return Result(layer=layer, timing=source.timing, inputs=inputs, summary=summary)


def _inputs(request: Request):
    from facedyn.dynamics.modelfile import load_model
    from facedyn.usd.errors import TakeError
    from facedyn.usd.take import read_take

    if len(request.inputs) != 1:
        raise UsageError("remove takes one TAKE")
    if not request.params["model"]:
        raise UsageError("remove needs --model MODEL (a file written by usdfacedyn train-removal)")
    # Read the stabilized take, under any earlier removal and the variants stacked on it.
    perf, source = read_take(request.inputs[0], frames=request.frames, mute=frozenset({"remove", "synthesize", "retarget", "preview"}))
    if source.skull_path is None or perf.skull_orient is None or perf.role == "captured":
        raise TakeError(f"{request.inputs[0]}: {source.mesh_path} is not stabilized; run `usdfacedyn stabilize` first")
    model = load_model(request.params["model"], topology=perf.topology, fps=perf.fps)
    if model.kind != "removal":
        raise UsageError(f"{request.params['model']}: a {model.kind} model; remove needs a removal model (network F)")
    return perf, source, model
