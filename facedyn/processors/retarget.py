"""The retarget processor: actor A's root motion onto actor B's quasistatic performance.

`--method synthesis` (default, the paper's): A's skull trajectory is moved into B's skull
space (facedyn.dynamics.root_motion.align_trajectory) and B's own synthesis model makes B's
dynamics for it. `--method delta-transfer`, the paper's naive baseline: A's per-vertex
offsets copied onto B. Both takes stream through in chunks (only the skull trajectories,
7 numbers a frame, are read whole), with the model's context frames, as in synthesize.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from facedyn.errors import UsageError
from facedyn.performance import BACKENDS, QUASISTATIC, RETARGETED, SYNTHESIZED
from facedyn.processors.base import INFERENCE_DEVICE, LayerOutput, Parameter, Plan, Processor, Reads, Request, Writes, single_input
from facedyn.processors.model_steps import SYNTHESIZES, OffsetStats, model_windows, reader_with_model, synthesized_chunk, synthesized_layer
from facedyn.progress import Progress


class RetargetProcessor(Processor):
    name = "retarget"
    version = "1"
    summary = "move actor A's root motion (and dynamics) onto actor B's quasistatic performance"
    reads = Reads("take", help="actor B's take root (reads its quasistatic take below any retargeted layer)")
    writes = Writes("layer", role=RETARGETED, help="the retargeted layer to write (.usdc)")
    parameters = (
        Parameter("source", Path, help="actor A's take: stabilized (synthesis) or with dynamics offsets (delta-transfer)", metavar="TAKE"),
        Parameter("model", Path, None, "actor B's synthesis model: network H or its linear response (method synthesis)", metavar="MODEL"),
        Parameter("method", str, "synthesis", "synthesis (B's network H) or delta-transfer (copy A's offsets)", ("synthesis", "delta-transfer")),
        Parameter("backend", str, "auto", "stretch kernels", BACKENDS),
        INFERENCE_DEVICE,
    )

    def prepare(self, request: Request) -> Plan:
        from facedyn.usd.errors import TakeError
        from facedyn.usd.frames import TakeFrames

        params = request.params
        if params["method"] == "synthesis":
            if params["model"] is None:
                raise UsageError("--model is required with --method synthesis (actor B's synthesis model)")
            reader, model = reader_with_model(request, self.writes.role, *SYNTHESIZES)
        else:
            if params["model"] is not None:
                raise UsageError("--model: delta-transfer uses no model; leave it out")
            reader, model = TakeFrames(single_input(request), self.writes.role, frames=request.frames), None
        # Actor A's skull motion is its stabilized take (below any quasistatic layer); its offsets, for
        # delta-transfer, are its quasistatic take's (below any synthesized variant).
        a = TakeFrames(params["source"], QUASISTATIC if params["method"] == "synthesis" else SYNTHESIZED)
        b = reader.head
        if a.head.skull_orient is None:
            raise TakeError(f"{params['source']}: actor A's take has no solved skull motion (stabilize it first)")
        if a.head.point_count != b.point_count:
            raise TakeError(f"{params['source']}: {a.head.point_count} points, the target take {b.point_count}; retargeting needs one topology")
        if abs(a.fps - reader.fps) > 1e-6:
            raise TakeError(f"{params['source']}: runs at {a.fps:g} fps, the target take at {reader.fps:g} fps")
        if a.frame_count < reader.frame_count:
            raise TakeError(f"{params['source']}: {a.frame_count} frames for a {reader.frame_count}-frame target take")
        if params["method"] == "delta-transfer" and a.head.offsets is None:
            raise TakeError(f"{params['source']}: delta-transfer needs actor A's dynamics offsets (its quasistatic layer)")
        description = {"target_take": str(request.inputs[0]), "source_take": str(params["source"]),
                       "frames": reader.frame_count, "method": params["method"]}
        return Plan(description, (reader, model, a, params))

    def run(self, plan: Plan, progress: Progress) -> LayerOutput:
        from facedyn.dynamics.root_motion import align_trajectory, delta_transfer, skull_correspondence
        from facedyn.dynamics.synthesis import synthesize_dynamics
        from facedyn.usd.runs import read_elsewhere

        reader, model, a, params = plan.state
        f = reader.frame_count
        rest_a, rest_b = rest_points(a), rest_points(reader)
        rigid = None
        weights = reader.head.rigid_weights
        if weights is not None and np.count_nonzero(weights >= 0.99) >= 3:
            rigid = np.flatnonzero(weights >= 0.99)
        t_a, q_a = a.skull()
        translate, orient = align_trajectory(t_a[:f], q_a[:f], rest_a, rest_b, vertices=rigid)
        rotation = skull_correspondence(rest_a, rest_b, rigid)[0] if model is None else None
        stats = OffsetStats("synthesized")

        def chunks():
            progress.start(f"retarget ({params['method']})", f)
            for window in model_windows(reader, model):
                if model is None:
                    points, offsets = delta_transfer(a.read(window.lo, window.hi).offsets, window.take.points, rotation)
                else:
                    points, offsets = synthesize_dynamics(window.take.points, translate[window.lo:window.hi],
                                                          orient[window.lo:window.hi], reader.fps, model,
                                                          backend=params["backend"], device=params["device"])
                yield synthesized_chunk(reader, window, points, offsets, translate, orient, stats)
                progress.advance(window.stop - window.start)
            progress.finish()

        stats.summary.update({"source": str(params["source"]), "method": params["method"]})
        output = synthesized_layer(reader.time_codes, reader.head.landmarks, reader.source, params["model"], self.writes.role,
                                   stats.summary)
        output.inputs = list(output.inputs) + read_elsewhere(a.source.inputs)  # actor A's layers, by content
        output.chunks = chunks()
        return output


def rest_points(reader) -> np.ndarray:
    """A take's rest mesh in skull space, else its first frame."""
    rest = reader.head.rest_points
    return rest if rest is not None else reader.read(0, 1).points[0]
