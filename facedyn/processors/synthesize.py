"""The synthesize processor: new secondary dynamics for a new skull motion (network H).

Writes `synthesized.NAME.usdc`: the new skull motion, points = quasistatic skin + the
synthesized offsets (propagated to the whole mesh), and the offsets primvar.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from facedyn.errors import UsageError
from facedyn.processors.base import Parameter, Processor, Request, Result
from facedyn.progress import Progress

# Variants stacked on a quasistatic take; synthesize and retarget read what lies below them.
VARIANT_PROCESSORS = frozenset({"synthesize", "retarget", "preview"})


class SynthesizeProcessor(Processor):
    name = "synthesize"
    version = "1"
    summary = "synthesize secondary dynamics for a (new) skull motion with a synthesis model (network H)"
    parameters = (
        Parameter("model", str, "", "the synthesis model file (from train-synthesis)"),
        Parameter("skull_motion", str, "", "BVH file, a stabilized take, or walk|run|hop|still|platform:9hz (default: the take's own)"),
        Parameter("joint", str, "Head", "BVH joint that carries the skull"),
        Parameter("seed", int, 0, "seed of a procedural motion"),
        Parameter("backend", str, "auto", "stretch kernels: auto, opencl, numpy", ("auto", "opencl", "numpy")),
        Parameter("device", str, "auto", "torch device for the network: auto, cpu, cuda"),
    )

    def check(self, request: Request) -> dict:
        perf, source, model = quasistatic_inputs(request, "synthesis")
        return {"take": str(request.inputs[0]), "frames": perf.frame_count,
                "skull motion": request.params["skull_motion"] or "the take's own"}

    def run(self, request: Request, progress: Progress) -> Result:
        from facedyn.dynamics.synthesis import synthesize_dynamics
        from facedyn.processors.motion_source import skull_motion

        perf, source, model = quasistatic_inputs(request, "synthesis")
        params = request.params
        if params["skull_motion"]:
            translate, orient, described = skull_motion(params["skull_motion"], perf.fps, perf.frame_count, params["joint"], params["seed"])
        else:
            (translate, orient), described = perf.skull(), "the take's own"
        progress.start("synthesize dynamics", 1)
        points, offsets = synthesize_dynamics(perf.points, translate, orient, perf.fps, model,
                                              backend=params["backend"], device=params["device"])
        progress.finish()
        return synthesized_result(perf, source, request, points, offsets, translate, orient, "synthesized",
                                  {"skull motion": described})


def quasistatic_inputs(request: Request, kind: str):
    """The quasistatic take and a model of `kind` that fits it."""
    from facedyn.dynamics.modelfile import load_model
    from facedyn.usd.errors import TakeError
    from facedyn.usd.take import read_take

    if len(request.inputs) != 1:
        raise UsageError("give one TAKE")
    if not request.params["model"]:
        raise UsageError(f"needs --model MODEL (a {kind} model file)")
    perf, source = read_take(request.inputs[0], frames=request.frames, mute=VARIANT_PROCESSORS)
    if perf.role != "quasistatic":
        raise TakeError(f"{request.inputs[0]}: {source.mesh_path} is {perf.role}, not quasistatic; run `usdfacedyn remove` first")
    model = load_model(request.params["model"], topology=perf.topology, fps=perf.fps)
    if model.kind != kind:
        raise UsageError(f"{request.params['model']}: a {model.kind} model; this needs a {kind} model")
    return perf, source, model


def synthesized_result(perf, source, request, points, offsets, translate, orient, role, extra):
    from facedyn.usd import schema
    from facedyn.usd.layers import LayerContent

    layer = LayerContent(
        frames=perf.frames, mesh_path=source.mesh_path, skull_path=source.skull_path, points=points, offsets=offsets,
        skull_translate=translate, skull_orient=orient, face=schema.FaceAttributes(role=role),
        skull=schema.SkullAttributes(solver="resampled", landmarks=perf.landmarks),
    )
    magnitude = np.linalg.norm(offsets, axis=-1)
    summary = dict(extra)
    summary.update({"peak offset (mm)": round(float(magnitude.max()) * 10, 3),
                    "RMS offset (mm)": round(float(np.sqrt(np.mean(magnitude**2))) * 10, 3)})
    inputs = list(source.layer_identifiers) + [str(Path(request.params["model"]).resolve())]
    return Result(layer=layer, timing=source.timing, inputs=inputs, summary=summary)
