"""The retarget processor: actor A's root motion onto actor B's quasistatic performance.

`--method synthesis` (default, the paper's): A's skull trajectory is moved into B's skull
space (facedyn.dynamics.retarget.align_trajectory) and B's own synthesis model makes B's
dynamics for it. `--method delta-transfer`, the paper's naive baseline: A's per-vertex
offsets copied onto B.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from facedyn.errors import UsageError
from facedyn.performance import BACKENDS
from facedyn.processors.base import LayerOutput, Parameter, Plan, Processor, Reads, Request, Writes, check_device, single_input
from facedyn.processors.synthesize import synthesized_output
from facedyn.progress import Progress


class RetargetProcessor(Processor):
    name = "retarget"
    version = "1"
    summary = "move actor A's root motion (and dynamics) onto actor B's quasistatic performance"
    reads = Reads("take", help="actor B's take root (reads its quasistatic take below any retargeted layer)")
    writes = Writes("layer", role="retargeted", help="the retargeted layer to write (.usdc)")
    parameters = (
        Parameter("source", Path, help="actor A's take: stabilized (synthesis) or with dynamics offsets (delta-transfer)", metavar="TAKE"),
        Parameter("model", Path, None, "actor B's synthesis model (method synthesis)", metavar="MODEL"),
        Parameter("method", str, "synthesis", "synthesis (B's network H) or delta-transfer (copy A's offsets)", ("synthesis", "delta-transfer")),
        Parameter("backend", str, "auto", "stretch kernels", BACKENDS),
        Parameter("device", str, "auto", "torch device for the network: auto, cpu, cuda, cuda:N", check=check_device),
    )

    def prepare(self, request: Request) -> Plan:
        from facedyn.processors.remove import read_with_model
        from facedyn.usd.errors import TakeError
        from facedyn.usd.take import read_take_below

        params = request.params
        if params["method"] == "synthesis":
            if params["model"] is None:
                raise UsageError("--model is required with --method synthesis (actor B's synthesis model)")
            perf, source, model = read_with_model(request, self.writes.role, "synthesis")
        else:
            if params["model"] is not None:
                raise UsageError("--model: delta-transfer uses no model; leave it out")
            path = single_input(request)
            perf, source = read_take_below(path, self.writes.role, frames=request.frames)
            model = None
        # Actor A's skull motion is its stabilized take (below any quasistatic layer); its offsets, for
        # delta-transfer, are its quasistatic take's (below any synthesized variant).
        a, _ = read_take_below(params["source"], "quasistatic" if params["method"] == "synthesis" else "synthesized")
        if a.skull_orient is None:
            raise TakeError(f"{params['source']}: actor A's take has no solved skull motion (stabilize it first)")
        if a.point_count != perf.point_count:
            raise TakeError(f"{params['source']}: {a.point_count} points, the target take {perf.point_count}; retargeting needs one topology")
        if abs(a.fps - perf.fps) > 1e-6:
            raise TakeError(f"{params['source']}: runs at {a.fps:g} fps, the target take at {perf.fps:g} fps")
        if a.frame_count < perf.frame_count:
            raise TakeError(f"{params['source']}: {a.frame_count} frames for a {perf.frame_count}-frame target take")
        if params["method"] == "delta-transfer" and a.offsets is None:
            raise TakeError(f"{params['source']}: delta-transfer needs actor A's dynamics offsets (its quasistatic layer)")
        description = {"target_take": str(request.inputs[0]), "source_take": str(params["source"]),
                       "frames": perf.frame_count, "method": params["method"]}
        return Plan(description, (perf, source, model, a, params))

    def run(self, plan: Plan, progress: Progress) -> LayerOutput:
        from facedyn.dynamics.retarget import align_trajectory, delta_transfer, skull_correspondence
        from facedyn.dynamics.synthesis import synthesize_dynamics

        perf, source, model, a, params = plan.state
        f = perf.frame_count
        rest_a = a.rest_points if a.rest_points is not None else a.points[0]
        rest_b = perf.rest_points if perf.rest_points is not None else perf.points[0]
        rigid = None
        if perf.rigid_weights is not None and np.count_nonzero(perf.rigid_weights >= 0.99) >= 3:
            rigid = np.flatnonzero(perf.rigid_weights >= 0.99)
        t_a, q_a = a.skull()
        translate, orient = align_trajectory(t_a[:f], q_a[:f], rest_a, rest_b, vertices=rigid)
        progress.start(f"retarget ({params['method']})", 1)
        if params["method"] == "synthesis":
            points, offsets = synthesize_dynamics(perf.points, translate, orient, perf.fps, model,
                                                  backend=params["backend"], device=params["device"])
        else:
            rotation, _ = skull_correspondence(rest_a, rest_b, rigid)
            points, offsets = delta_transfer(a.offsets[:f], perf.points, rotation)
        progress.finish()
        return synthesized_output(perf, source, params["model"], points, offsets, translate, orient, self.writes.role,
                                  {"source": str(params["source"]), "method": params["method"]})
