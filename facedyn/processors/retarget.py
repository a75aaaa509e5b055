"""The retarget processor: actor A's root motion onto actor B's quasistatic performance.

`--method synthesis` (default, the paper's): A's skull trajectory is moved into B's skull
space (facedyn.dynamics.retarget.align_trajectory) and B's own synthesis model makes B's
dynamics for it. `--method delta-transfer`, the paper's naive baseline: A's per-vertex
offsets copied onto B.
"""
from __future__ import annotations

import numpy as np

from facedyn.errors import UsageError
from facedyn.processors.base import Parameter, Processor, Request, Result
from facedyn.processors.synthesize import VARIANT_PROCESSORS, quasistatic_inputs, synthesized_result
from facedyn.progress import Progress


class RetargetProcessor(Processor):
    name = "retarget"
    version = "1"
    summary = "move actor A's root motion (and dynamics) onto actor B's quasistatic performance"
    parameters = (
        Parameter("source", str, "", "actor A's take: stabilized (synthesis) or with dynamics offsets (delta-transfer)"),
        Parameter("model", str, "", "actor B's synthesis model (method synthesis)"),
        Parameter("method", str, "synthesis", "synthesis (B's network H) or delta-transfer (copy A's offsets)", ("synthesis", "delta-transfer")),
        Parameter("backend", str, "auto", "stretch kernels: auto, opencl, numpy", ("auto", "opencl", "numpy")),
        Parameter("device", str, "auto", "torch device for the network: auto, cpu, cuda"),
    )

    def check(self, request: Request) -> dict:
        perf, _, _, source_perf = self._inputs(request)
        return {"target take": str(request.inputs[0]), "source take": request.params["source"],
                "frames": perf.frame_count, "method": request.params["method"]}

    def run(self, request: Request, progress: Progress) -> Result:
        from facedyn.dynamics.retarget import align_trajectory, delta_transfer, skull_correspondence
        from facedyn.dynamics.synthesis import synthesize_dynamics

        perf, source, model, a = self._inputs(request)
        f = perf.frame_count
        rest_a = a.rest_points if a.rest_points is not None else a.points[0]
        rest_b = perf.rest_points if perf.rest_points is not None else perf.points[0]
        rigid = None
        if perf.rigid_weights is not None and np.count_nonzero(perf.rigid_weights >= 0.99) >= 3:
            rigid = np.flatnonzero(perf.rigid_weights >= 0.99)
        t_a, q_a = a.skull()
        translate, orient = align_trajectory(t_a[:f], q_a[:f], rest_a, rest_b, vertices=rigid)
        progress.start(f"retarget ({request.params['method']})", 1)
        if request.params["method"] == "synthesis":
            points, offsets = synthesize_dynamics(perf.points, translate, orient, perf.fps, model,
                                                  backend=request.params["backend"], device=request.params["device"])
        else:
            rotation, _ = skull_correspondence(rest_a, rest_b, rigid)
            points, offsets = delta_transfer(a.offsets[:f], perf.points, rotation)
        progress.finish()
        return synthesized_result(perf, source, request, points, offsets, translate, orient, "retargeted",
                                  {"source": request.params["source"], "method": request.params["method"]})

    def _inputs(self, request: Request):
        from facedyn.usd.errors import TakeError
        from facedyn.usd.take import read_take

        params = request.params
        if not params["source"]:
            raise UsageError("retarget needs --source TAKE (actor A's take)")
        if params["method"] == "synthesis":
            perf, source, model = quasistatic_inputs(request, "synthesis")
        else:
            if params["model"]:
                raise UsageError("delta-transfer uses no model; leave out --model")
            perf, source = read_take(request.inputs[0], frames=request.frames, mute=VARIANT_PROCESSORS)
            model = None
            if perf.role != "quasistatic":
                raise TakeError(f"{request.inputs[0]}: {source.mesh_path} is {perf.role}, not quasistatic; run `usdfacedyn remove` first")
        a, a_source = read_take(params["source"], mute=VARIANT_PROCESSORS)
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
        return perf, source, model, a
