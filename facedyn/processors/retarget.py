"""The retarget processor: actor A's root motion onto actor B's quasistatic performance.

`--method synthesis` (default, the paper's): A's skull trajectory is moved into B's skull
space (facedyn.dynamics.root_motion.align_trajectory) and B's own synthesis model makes B's
dynamics for it. `--method delta-transfer`, the paper's naive baseline: A's per-vertex
offsets copied onto B. `--method residual`: B's synthesis, plus what A's removal found in
A's capture beyond what A's own synthesis model (`--source-model`, default `--model`: one
actor) makes for A's quasistatic take under A's skull (facedyn.dynamics.root_motion.
residual_transfer): a synthesis model reads the skull alone and misses what the capture
showed, so B gets the part of A's dynamics that B's model can say and the part that only
A's capture could. For one actor it comes close to delta transfer, which copies the
actor's own tissue, and across actors it keeps B's tissue for what the skull drives
(README's retargeting figures). All stream through in chunks (only the skull
trajectories, 7 numbers a frame, are read whole), with the models' context frames, as in
synthesize.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from facedyn.errors import UsageError
from facedyn.performance import BACKENDS, QUASISTATIC, RETARGETED, SYNTHESIZED
from facedyn.processors.base import INFERENCE_DEVICE, LayerOutput, Parameter, Plan, Processor, Reads, Request, Writes, single_input
from facedyn.processors.model_steps import (SYNTHESIZES, OffsetStats, check_skull_frame, model_windows, reader_with_model, synthesized_chunk,
                                           synthesized_layer)
from facedyn.progress import Progress


class RetargetProcessor(Processor):
    name = "retarget"
    version = "1"
    summary = "move actor A's root motion (and dynamics) onto actor B's quasistatic performance"
    reads = Reads("take", help="actor B's take root (reads its quasistatic take below any retargeted layer)")
    writes = Writes("layer", role=RETARGETED, help="the retargeted layer to write (.usdc)")
    parameters = (
        Parameter("source", Path, help="actor A's take: stabilized (synthesis), with dynamics offsets (delta-transfer, residual)",
                  metavar="TAKE"),
        Parameter("model", Path, None, "actor B's synthesis model: network H or its linear response (methods synthesis, residual)",
                  metavar="MODEL"),
        Parameter("method", str, "synthesis", "synthesis (B's model), delta-transfer (copy A's offsets) or residual (B's model plus "
                  "what A's removal found beyond A's model)", ("synthesis", "delta-transfer", "residual")),
        Parameter("source_model", Path, None, "actor A's synthesis model or linear response (method residual; default --model, "
                  "when A and B are one actor)", metavar="MODEL"),
        Parameter("backend", str, "auto", "stretch kernels", BACKENDS),
        INFERENCE_DEVICE,
    )

    def prepare(self, request: Request) -> Plan:
        from facedyn.usd.errors import TakeError
        from facedyn.usd.frames import TakeFrames

        params = request.params
        method = params["method"]
        if params["source_model"] is not None and method != "residual":
            raise UsageError(f"--source-model: only --method residual reads actor A's model; {method} does not")
        if method == "delta-transfer":
            if params["model"] is not None:
                raise UsageError("--model: delta-transfer uses no model; leave it out")
            reader, model = TakeFrames(single_input(request), self.writes.role, frames=request.frames), None
        else:
            if params["model"] is None:
                raise UsageError(f"--model is required with --method {method} (actor B's synthesis model)")
            reader, model = reader_with_model(request, self.writes.role, *SYNTHESIZES)
        # Actor A's skull motion is its stabilized take (below any quasistatic layer); its offsets, for
        # delta-transfer and residual, are its quasistatic take's (below any synthesized variant).
        a = TakeFrames(params["source"], QUASISTATIC if method == "synthesis" else SYNTHESIZED)
        b = reader.head
        if a.head.skull_orient is None:
            raise TakeError(f"{params['source']}: actor A's take has no solved skull motion (stabilize it first)")
        if a.head.point_count != b.point_count:
            raise TakeError(f"{params['source']}: {a.head.point_count} points, the target take {b.point_count}; retargeting needs one topology")
        if abs(a.fps - reader.fps) > 1e-6:
            raise TakeError(f"{params['source']}: runs at {a.fps:g} fps, the target take at {reader.fps:g} fps")
        if a.frame_count < reader.frame_count:
            raise TakeError(f"{params['source']}: {a.frame_count} frames for a {reader.frame_count}-frame target take")
        if method != "synthesis" and a.head.offsets is None:
            raise TakeError(f"{params['source']}: {method} needs actor A's dynamics offsets (its quasistatic layer: "
                            "`usdfacedyn remove` it first)")
        source_model = source_model_of(params, a, model) if method == "residual" else None
        description = {"target_take": str(request.inputs[0]), "source_take": str(params["source"]),
                       "frames": reader.frame_count, "method": method}
        return Plan(description, (reader, model, a, source_model, params))

    def run(self, plan: Plan, progress: Progress) -> LayerOutput:
        from facedyn.dynamics.root_motion import align_trajectory, delta_transfer, residual_transfer, skull_correspondence
        from facedyn.dynamics.synthesis import synthesize_dynamics
        from facedyn.usd.runs import read_elsewhere

        reader, model, a, source_model, params = plan.state
        method = params["method"]
        f = reader.frame_count
        rest_a, rest_b = rest_points(a), rest_points(reader)
        rigid = None
        weights = reader.head.rigid_weights
        if weights is not None and np.count_nonzero(weights >= 0.99) >= 3:
            rigid = np.flatnonzero(weights >= 0.99)
        t_a, q_a = a.skull()
        translate, orient = align_trajectory(t_a[:f], q_a[:f], rest_a, rest_b, vertices=rigid)
        rotation = skull_correspondence(rest_a, rest_b, rigid)[0] if method != "synthesis" else None
        stats = OffsetStats("synthesized")

        def synthesized(window):
            return synthesize_dynamics(window.take.points, translate[window.lo:window.hi], orient[window.lo:window.hi],
                                       reader.fps, model, backend=params["backend"], device=params["device"])

        def chunks():
            progress.start(f"retarget ({method})", f)
            for window in model_windows(reader, model, source_model):
                if method == "delta-transfer":
                    points, offsets = delta_transfer(a.read(window.lo, window.hi).offsets, window.take.points, rotation)
                elif method == "residual":
                    source = a.read(window.lo, window.hi)
                    _, own = synthesize_dynamics(source.points, t_a[window.lo:window.hi], q_a[window.lo:window.hi], reader.fps,
                                                 source_model, backend=params["backend"], device=params["device"])
                    points, offsets = residual_transfer(*synthesized(window), source.offsets, own, rotation)
                else:
                    points, offsets = synthesized(window)
                yield synthesized_chunk(reader, window, points, offsets, translate, orient, stats)
                progress.advance(window.stop - window.start)
            progress.finish()

        stats.summary.update({"source": str(params["source"]), "method": method})
        output = synthesized_layer(reader.time_codes, reader.head.landmarks, reader.source, [params["model"], params["source_model"]],
                                   self.writes.role, stats.summary)
        output.inputs = list(output.inputs) + read_elsewhere(a.source.inputs)  # actor A's layers, by content
        output.chunks = chunks()
        return output


def source_model_of(params: dict, a, model):
    """Actor A's synthesis model (or linear response) for --method residual: --source-model, else B's `model` (one
    actor: A's take has B's topology and frame rate, checked); it must fit A's take as B's model fits B's."""
    from facedyn.dynamics.modelfile import load_model

    path = params["source_model"]
    if path is not None:
        model = load_model(path, topology=a.head.topology, fps=a.fps)
        if model.kind not in SYNTHESIZES:
            raise UsageError(f"--source-model {path}: a {model.kind} model; actor A's own synthesis model or linear response is needed")
    check_skull_frame(params["source"], a.head, path or params["model"], model)
    return model


def rest_points(reader) -> np.ndarray:
    """A take's rest mesh in skull space, else its first frame."""
    rest = reader.head.rest_points
    return rest if rest is not None else reader.read(0, 1).points[0]
