"""What the steps that apply a dynamics model to a take share: the model's checks, the chunks, the layers.

`remove`, `synthesize`, `retarget`, `evaluate` and `preview` are processors; this is their library
(no processor imports another). A take streams through in chunks of CHUNK_FRAMES output frames, each
read with the frames of context the model's windows reach (context_frames), so the result equals the
whole take's and memory is bounded by a chunk. A model is checked to fit the take (topology, frame
rate, skull frame) and to be of a kind the step takes: REMOVES (network F, an actor's linear
response) or SYNTHESIZES (network H, a linear response).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from facedyn.errors import UsageError
from facedyn.processors.base import LayerOutput, Request, single_input

CHUNK_FRAMES = 1024  # frames computed, held and written (one value clip of a long take) at a time
REMOVES = ("removal", "response")  # the model kinds that remove: network F, an actor's linear response
SYNTHESIZES = ("synthesis", "response")  # the model kinds that synthesize: network H, an actor's linear response


def model_windows(reader, *models, reach: int = 0):
    """The reader's chunks of CHUNK_FRAMES output frames, each with the context the models' windows reach (none
    without a model; a None model is none), plus `reach` frames (what a blend's band filters read of their results)."""
    return reader.windows(CHUNK_FRAMES, max((context_frames(model) for model in models if model is not None), default=0) + reach)


def take_reader(request: Request, role_name: str):
    """The take below `role_name`, as a chunked reader (facedyn.usd.frames)."""
    from facedyn.usd.frames import TakeFrames

    return TakeFrames(single_input(request), role_name, frames=request.frames)


def reader_with_model(request: Request, role_name: str, *kinds: str):
    """The take below `role_name` (a chunked reader, facedyn.usd.frames) and a model of one of `kinds` that fits it."""
    from facedyn.dynamics.modelfile import load_model

    reader = take_reader(request, role_name)
    model = load_model(request.params["model"], topology=reader.head.topology, fps=reader.fps)
    if model.kind not in kinds:
        raise UsageError(f"--model {request.params['model']}: a {model.kind} model; this step needs a {' or '.join(kinds)} model")
    check_skull_frame(request.inputs[0], reader.head, request.params["model"], model)
    return reader, model


def removal_models(path: Path, flag: str, perf, fps: float, take: Path) -> tuple[list, object]:
    """The models a removal file holds (one, or a blend's members) that fit the take: removal
    models (F) and linear responses, never a synthesis network; and how their removals blend
    (facedyn.dynamics.bands.BandWeights)."""
    from facedyn.dynamics.modelfile import load_models
    from facedyn.dynamics.portable import for_take, is_portable
    from facedyn.models import resolve_model

    path = resolve_model(path, flag)
    models, weights = load_models(path, topology=perf.topology, fps=fps)
    for model in models:
        if model.kind not in REMOVES:
            raise UsageError(f"--{flag} {path}: a synthesis model (network H), which reads the quasistatic shape it would "
                             "make; this needs a removal model (F), an actor's linear response (.response) or a blend of them")
        check_skull_frame(take, perf, path, model)
    return [for_take(model, perf) if is_portable(model) else model for model in models], weights


def removal_blend(model: Path, blend: Path | None, perf, fps: float, take: Path) -> tuple[list, object]:
    """[(file, model)]: --model's models, and --blend's, whose removals are averaged with them; and how
    their removals blend (facedyn.dynamics.bands.BandWeights): the file's own weights, or with --blend the mean."""
    from facedyn.dynamics.bands import BandWeights

    models, weights = removal_models(model, "model", perf, fps, take)
    if blend is None:
        return [(model, m) for m in models], weights
    more, more_weights = removal_models(blend, "blend", perf, fps, take)
    for path, held in ((model, weights), (blend, more_weights)):
        if not held.is_mean():
            raise UsageError(f"--blend {blend}: --blend averages removals, and {path} weighs its members per frequency band; "
                             "give that blend alone, as --model")
    return [(model, m) for m in models] + [(blend, m) for m in more], BandWeights.mean(len(models) + len(more))


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


def removal_of(points, translate, orient, fps: float, model, backend: str = "auto", device: str = "auto") -> tuple[np.ndarray, np.ndarray]:
    """(quasistatic skull-space points, offsets) of stabilized points removed by a removal
    model (F) or an actor's linear response."""
    from facedyn.dynamics.removal import remove_dynamics
    from facedyn.dynamics.response import remove_with_response

    if model.kind == "removal":
        return remove_dynamics(points, translate, orient, fps, model, backend=backend, device=device)
    return remove_with_response(points, translate, orient, fps, model)


def session_motion_left(takes, names: tuple[str, ...], skip_s: float, band_pair: tuple[str, str] | None = None) -> dict:
    """{removal: the fraction of a calibration session's motion it leaves beyond held shapes
    and sag}, `evaluate --session`'s figure (facedyn.dynamics.diagnostics.SessionScore).

    takes: (Performance, {removal name: its offsets (F, N, 3)}) one take at a time (a
    generator keeps one take's removals in memory); the Performance's points (plus the
    offsets it holds, when its removal was read from its layers) are the capture. Every
    removal is scored in the same pass, each take's capture cleaned of tracker spikes once.
    With band_pair (a, b), two of the removals, also "bands": the figure of their blend
    with the per-band weights that leave the least (facedyn.dynamics.bands.BandWeightsFit),
    and "band_weights", that blend (a BandWeights of members a, b).
    """
    from facedyn.dynamics.bands import BandWeightsFit
    from facedyn.dynamics.diagnostics import SessionScore

    score, fit = None, None if band_pair is None else BandWeightsFit()
    for perf, offsets in takes:
        skip = int(round(skip_s * perf.fps))
        if perf.frame_count <= skip + 2:
            raise UsageError(f"--skip {skip_s:g}: leaves too few of a session take's {perf.frame_count} frames")
        if score is None:
            vertices = np.arange(perf.point_count) if perf.face_vertices is None else np.asarray(perf.face_vertices)
            score = SessionScore(vertices, skip, names)
        captured = perf.points if perf.offsets is None else perf.points + perf.offsets
        cleaned, rotations = score.add(captured, perf.skull()[1], offsets)
        if fit is not None:
            a, b = (np.asarray(offsets[name])[:, score.vertices].reshape(perf.frame_count, -1) for name in band_pair)
            fit.add(cleaned, rotations, a, b, perf.fps, skip)
    if score is None:
        raise UsageError("a session figure needs at least one take")
    figures = {name: round(left, 4) for name, left in score.motion_left().items()}
    if fit is not None:
        weights = fit.weights()
        figures["bands"] = round(fit.left(weights.weights[:, 0]) / max(score.motion.norm(), 1e-30), 4)
        figures["band_weights"] = weights
    return figures


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


def model_inputs(source, *model_paths: Path) -> list[str]:
    """The provenance inputs of a layer computed from a take and model files (a shipped model's name as its file)."""
    from facedyn.models import resolve_model

    return list(source.inputs) + [str(resolve_model(path).resolve()) for path in model_paths]


def synthesized_chunk(reader, window, points, offsets, translate, orient, stats):
    """One window's output frames of a synthesized layer (synthesize and retarget write the same shape):
    points and offsets computed over the window's frames, the skull motion over the take's."""
    from facedyn.usd.layers import LayerContent

    inner = window.inner
    return LayerContent(frames=reader.time_codes[window.start:window.stop], points=points[inner],
                        offsets=stats.add(offsets[inner]), skull_translate=translate[window.start:window.stop],
                        skull_orient=orient[window.start:window.stop])


def synthesized_layer(frames, landmarks, source, model_paths, role_name, summary) -> LayerOutput:
    """The static part of a synthesized layer (its per-frame values come as arrays or chunks); model_paths:
    the model files it applied (inputs of the layer)."""
    from facedyn.usd import schema
    from facedyn.usd.layers import LayerContent

    layer = LayerContent(
        frames=frames, mesh_path=source.mesh_path, skull_path=source.skull_path, face=schema.FaceAttributes(role=role_name),
        skull=schema.SkullAttributes(solver="resampled", landmarks=landmarks),
    )
    inputs = model_inputs(source, *(path for path in model_paths if path is not None))
    return LayerOutput(layer=layer, timing=source.timing, inputs=inputs, summary=summary)


class OffsetStats:
    """Peak and RMS offset magnitude accumulated chunk by chunk; `summary` fills in as chunks pass."""

    def __init__(self, what: str):
        self.what, self.peak, self.squares, self.count = what, 0.0, 0.0, 0
        self.summary: dict = {}

    def add(self, offsets: np.ndarray) -> np.ndarray:
        flat = np.asarray(offsets).reshape(-1, 3)
        squared = np.einsum("ij,ij->i", flat, flat)  # one pass, no norm's square root per point (a quarter of the time)
        self.peak = max(self.peak, float(np.sqrt(squared.max(initial=0.0))))
        self.squares += float(squared.sum(dtype=np.float64))
        self.count += len(squared)
        if self.count:
            self.summary.update({f"peak_{self.what}_offset_mm": round(self.peak * 10, 3),
                                 f"rms_{self.what}_offset_mm": round(float(np.sqrt(self.squares / self.count)) * 10, 3)})
        return offsets
