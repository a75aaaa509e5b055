"""The remove processor: subtract the secondary dynamics that network F predicts.

Reads the stabilized take (the layers below the quasistatic role) and writes the
quasistatic layer: points = the quasistatic skin in skull space, and the removed dynamics
as `primvars:facedyn:dynamicsOffset` (captured - quasistatic). F's features are skull
landmark motion in the skull frame, so the take must be stabilized.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from facedyn.errors import UsageError
from facedyn.performance import BACKENDS
from facedyn.processors.base import LayerOutput, Parameter, Plan, Processor, Reads, Request, Writes, check_device, single_input
from facedyn.progress import Progress


class RemoveProcessor(Processor):
    name = "remove"
    version = "1"
    summary = "remove secondary dynamics with a trained removal model (network F)"
    reads = Reads("take", help="the take root (reads the stabilized take below any quasistatic layer)")
    writes = Writes("layer", role="quasistatic", help="the quasistatic layer to write (.usdc)")
    parameters = (
        Parameter("model", Path, help="the removal model file (from train-removal)", metavar="MODEL"),
        Parameter("backend", str, "auto", "feature and Laplacian kernels", BACKENDS),
        Parameter("device", str, "auto", "torch device for the network: auto, cpu, cuda, cuda:N", check=check_device),
    )

    def prepare(self, request: Request) -> Plan:
        perf, source, model = read_with_model(request, self.writes.role, "removal")
        description = {"take": str(request.inputs[0]), "frames": perf.frame_count, "model": str(request.params["model"]),
                       "samples": int(len(model.face.samples))}
        return Plan(description, (perf, source, model, request.params))

    def run(self, plan: Plan, progress: Progress) -> LayerOutput:
        from facedyn.dynamics.removal import remove_dynamics
        from facedyn.usd import schema
        from facedyn.usd.layers import LayerContent

        perf, source, model, params = plan.state
        translate, orient = perf.skull()
        progress.start("remove dynamics", 1)
        quasistatic, offsets = remove_dynamics(perf.points, translate, orient, perf.fps, model,
                                               backend=params["backend"], device=params["device"])
        progress.finish()
        layer = LayerContent(
            frames=perf.frames, mesh_path=source.mesh_path, skull_path=source.skull_path, points=quasistatic, offsets=offsets,
            face=schema.FaceAttributes(role=self.writes.role, skin_samples=model.face.samples),
        )
        return LayerOutput(layer=layer, timing=source.timing, inputs=model_inputs(source, params["model"]),
                           summary=offset_summary(offsets, "removed"))


def read_with_model(request: Request, role_name: str, kind: str):
    """The take below `role_name` and a model of `kind` that fits it (topology, frame rate)."""
    from facedyn.dynamics.modelfile import load_model
    from facedyn.usd.take import read_take_below

    path = single_input(request)
    perf, source = read_take_below(path, role_name, frames=request.frames)
    model = load_model(request.params["model"], topology=perf.topology, fps=perf.fps)
    if model.kind != kind:
        raise UsageError(f"--model {request.params['model']}: a {model.kind} model; this step needs a {kind} model")
    check_skull_frame(path, perf, request.params["model"], model)
    return perf, source, model


def check_skull_frame(path: Path, perf, model_path: Path, model) -> None:
    """A model predicts in the skull frame it was trained in: refuse a take stabilized in another."""
    from facedyn.processors.training_inputs import take_skull_frame
    from facedyn.usd.errors import TakeError

    expected = model.info.get("skull_frame")
    if expected is None:  # trained on takes without a rest mesh, or before models recorded it
        return
    found = take_skull_frame(perf)
    if found != expected:
        what = "has no actor's skull frame (a plain take stabilized without --actor)" if found is None else "is in another skull frame"
        raise TakeError(f"{path}: the take {what}, not the one {model_path} was trained in; stabilize it with "
                        "--actor ACTOR, the actor made from the rig or takes the model was trained on")


def model_inputs(source, model_path: Path) -> list[str]:
    """The provenance inputs of a layer computed from a take and a model file."""
    return list(source.inputs) + [str(Path(model_path).resolve())]


def offset_summary(offsets: np.ndarray, what: str) -> dict:
    magnitude = np.linalg.norm(offsets, axis=-1)
    return {f"peak_{what}_offset_mm": round(float(magnitude.max()) * 10, 3),
            f"rms_{what}_offset_mm": round(float(np.sqrt(np.mean(magnitude**2))) * 10, 3)}
