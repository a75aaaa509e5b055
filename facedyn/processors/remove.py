"""The remove processor: subtract the secondary dynamics that network F predicts.

Or that an actor's linear response predicts from the skull alone (a .response file from
`train-synthesis --response linear`, facedyn.dynamics.response): `--model` takes either, or
a blend file (`usdfacedyn calibrate`'s `removal.blend`), which removes the mean of its
members' dynamics, as `--blend MODEL` does for two files (F's and the actor's response,
whose errors are partly independent); `usdfacedyn evaluate --session --removal M --blend N`
scores the mean on the actor's session before a take is touched. A synthesis network H is
never a removal.

Reads the stabilized take (the layers below the quasistatic role) and writes the
quasistatic layer: points = the quasistatic skin in skull space, and the removed dynamics
as `primvars:facedyn:dynamicsOffset` (captured - quasistatic). F's features are skull
landmark motion in the skull frame, so the take must be stabilized.

The take streams through in chunks of CHUNK_FRAMES, each read with the frames of context
the model's windows reach (context_frames), so the result equals the whole take's and
memory is bounded by a chunk.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from facedyn.errors import UsageError
from facedyn.performance import BACKENDS
from facedyn.processors.base import LayerOutput, Parameter, Plan, Processor, Reads, Request, Writes, check_device, single_input
from facedyn.progress import Progress

CHUNK_FRAMES = 1024  # frames computed, held and written (one value clip of a long take) at a time
REMOVES = ("removal", "response")  # the model kinds that remove: network F, an actor's linear response


class RemoveProcessor(Processor):
    name = "remove"
    version = "1"
    summary = "remove secondary dynamics with a trained removal model (network F) or an actor's linear response"
    reads = Reads("take", help="the take root (reads the stabilized take below any quasistatic layer)")
    writes = Writes("layer", role="quasistatic", help="the quasistatic layer to write (.usdc)")
    parameters = (
        Parameter("model", Path, help="the removal model file (from train-removal), an actor's linear response "
                  "(.response, train-synthesis --response linear), a blend of them (calibrate's removal.blend), or `default`: "
                  "the shipped person-independent removal model, for an actor with neither rig nor session", metavar="MODEL"),
        Parameter("blend", Path, None, "a second removal model or linear response: remove the mean of the two models' dynamics",
                  metavar="MODEL"),
        Parameter("backend", str, "auto", "feature and Laplacian kernels", BACKENDS),
        Parameter("device", str, "auto", "torch device for the network: auto, cpu, cuda, cuda:N", check=check_device),
    )

    def prepare(self, request: Request) -> Plan:
        params = request.params
        reader = take_reader(request, self.writes.role)
        models = removal_models(params["model"], "model", reader.head, reader.fps, request.inputs[0])
        if params["blend"] is not None:
            models += removal_models(params["blend"], "blend", reader.head, reader.fps, request.inputs[0])
        description = {"take": str(request.inputs[0]), "frames": reader.frame_count, "model": str(params["model"]),
                       "blend": str(params["blend"] or ""), "samples": int(len(models[0].face.samples)),
                       **{f"face_{key}": models[0].info[key] for key in ("rest", "facing") if key in models[0].info}}  # a per-take setup's
        return Plan(description, (reader, models, params))

    def run(self, plan: Plan, progress: Progress) -> LayerOutput:
        from facedyn.usd import schema
        from facedyn.usd.layers import LayerContent

        reader, models, params = plan.state
        source = reader.source
        layer = LayerContent(frames=reader.time_codes, mesh_path=source.mesh_path, skull_path=source.skull_path,
                             face=schema.FaceAttributes(role=self.writes.role, skin_samples=models[0].face.samples))
        stats = OffsetStats("removed")

        def chunks():
            progress.start("remove dynamics", reader.frame_count)
            for window in reader.windows(CHUNK_FRAMES, max(map(context_frames, models))):
                removed = [removal_of(window.take.points, *window.take.skull(), reader.fps, model, params["backend"], params["device"])
                           for model in models]
                quasistatic, offsets = mean_removal(removed)
                yield LayerContent(frames=reader.time_codes[window.start:window.stop], points=quasistatic[window.inner],
                                   offsets=stats.add(offsets[window.inner]))
                progress.advance(window.stop - window.start)
            progress.finish()

        paths = [params["model"]] + ([params["blend"]] if params["blend"] is not None else [])
        return LayerOutput(layer=layer, timing=source.timing, inputs=model_inputs(source, *paths),
                           summary=stats.summary, chunks=chunks())


def take_reader(request: Request, role_name: str):
    """The take below `role_name`, as a chunked reader (facedyn.usd.frames)."""
    from facedyn.usd.frames import TakeFrames

    return TakeFrames(single_input(request), role_name, frames=request.frames)


def removal_models(path: Path, flag: str, perf, fps: float, take: Path) -> list:
    """The models a removal file holds (one, or a blend's members) that fit the take: removal
    models (F) and linear responses, never a synthesis network."""
    from facedyn.dynamics.modelfile import load_models
    from facedyn.dynamics.portable import for_take, is_portable
    from facedyn.models import resolve_model

    path = resolve_model(path, flag)
    models = load_models(path, topology=perf.topology, fps=fps)
    for model in models:
        if model.kind not in REMOVES:
            raise UsageError(f"--{flag} {path}: a synthesis model (network H), which reads the quasistatic shape it would "
                             "make; this needs a removal model (F), an actor's linear response (.response) or a blend of them")
        check_skull_frame(take, perf, path, model)
    return [for_take(model, perf) if is_portable(model) else model for model in models]


def removal_of(points, translate, orient, fps: float, model, backend: str = "auto", device: str = "auto") -> tuple[np.ndarray, np.ndarray]:
    """(quasistatic skull-space points, offsets) of stabilized points removed by a removal
    model (F) or an actor's linear response."""
    from facedyn.dynamics.removal import remove_dynamics
    from facedyn.dynamics.response import remove_with_response

    if model.kind == "removal":
        return remove_dynamics(points, translate, orient, fps, model, backend=backend, device=device)
    return remove_with_response(points, translate, orient, fps, model, device=device)


def mean_removal(removed: list) -> tuple[np.ndarray, np.ndarray]:
    """(quasistatic points, offsets), float32: the mean of one take's removals by several models (--blend)."""
    if len(removed) == 1:
        return removed[0]
    return tuple(np.mean([r[i] for r in removed], axis=0).astype(np.float32) for i in (0, 1))


def reader_with_model(request: Request, role_name: str, *kinds: str):
    """The take below `role_name` (a chunked reader, facedyn.usd.frames) and a model of one of `kinds` that fits it."""
    from facedyn.dynamics.modelfile import load_model

    reader = take_reader(request, role_name)
    model = load_model(request.params["model"], topology=reader.head.topology, fps=reader.fps)
    if model.kind not in kinds:
        raise UsageError(f"--model {request.params['model']}: a {model.kind} model; this step needs a {' or '.join(kinds)} model")
    check_skull_frame(request.inputs[0], reader.head, request.params["model"], model)
    return reader, model


def context_frames(model) -> int:
    """Frames of context on each side that make a chunk's result equal to the whole take's.

    Every window a model reads (feature windows, skull motion past and future, smoothing),
    plus the frames its velocities and accelerations difference over, and for F the frames
    a spike replacement looks at (facedyn.dynamics.spikes). A linear response's expression
    term reads the skin (spikes replaced) less the skull-driven dynamics, low-passed, through
    its own skull window again (facedyn.dynamics.expression_inertia), and its stiffening
    reads the response over that window once more (facedyn.dynamics.hardening).
    """
    from facedyn.dynamics.expression_inertia import filter_reach
    from facedyn.dynamics.spikes import REACH

    motion = model.skull_input
    frames = sum(int(w) for w in model.windows.values()) + motion.past + motion.future + 4
    if model.kind == "removal":  # F reads the skin with its spikes replaced
        return frames + REACH
    calibration = model.info.get("calibration", {})
    if calibration.get("hardening"):  # its stiffening reads the response over its skull window
        frames += motion.past + motion.future
    lowpass = calibration.get("expression_inertia_hz")
    return frames if lowpass is None else frames + REACH + motion.past + motion.future + filter_reach(model.fps, lowpass)


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


def model_inputs(source, *model_paths: Path) -> list[str]:
    """The provenance inputs of a layer computed from a take and model files (a shipped model's name as its file)."""
    from facedyn.models import resolve_model

    return list(source.inputs) + [str(resolve_model(path).resolve()) for path in model_paths]


class OffsetStats:
    """Peak and RMS offset magnitude accumulated chunk by chunk; `summary` fills in as chunks pass."""

    def __init__(self, what: str):
        self.what, self.peak, self.squares, self.count = what, 0.0, 0.0, 0
        self.summary: dict = {}

    def add(self, offsets: np.ndarray) -> np.ndarray:
        magnitude = np.linalg.norm(offsets, axis=-1)
        self.peak = max(self.peak, float(magnitude.max()))
        self.squares += float(np.sum(magnitude.astype(np.float64) ** 2))
        self.count += magnitude.size
        self.summary.update({f"peak_{self.what}_offset_mm": round(self.peak * 10, 3),
                             f"rms_{self.what}_offset_mm": round(float(np.sqrt(self.squares / self.count)) * 10, 3)})
        return offsets
