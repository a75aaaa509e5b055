"""The synthesize processor: new secondary dynamics for a (new) skull motion (network H).

Reads the quasistatic take (the layers below the synthesized role, so other synthesized
variants never feed back) and writes `synthesized.NAME.usdc`: the new skull motion,
points = quasistatic skin + the synthesized offsets (propagated to the whole mesh), and the
offsets primvar. The take streams through in chunks with the model's context frames, as in
remove (facedyn.processors.model_steps).
"""
from __future__ import annotations

from pathlib import Path

from facedyn.errors import UsageError
from facedyn.performance import BACKENDS, SYNTHESIZED
from facedyn.processors.base import INFERENCE_DEVICE, LayerOutput, Parameter, Plan, Processor, Reads, Request, Writes
from facedyn.processors.model_steps import SYNTHESIZES, OffsetStats, model_windows, reader_with_model, synthesized_chunk, synthesized_layer
from facedyn.progress import Progress


AXES = ("+x", "-x", "+y", "-y", "+z", "-z")
BVH_PARAMETERS = (
    Parameter("bvh_units", float, None, "cm per BVH unit (default: from the skeleton's height; CMU files 5.64)",
              above=0.0, maximum=1000.0, metavar="CM"),
    Parameter("bvh_up", str, None, "the BVH's up axis (default: from the skeleton)", AXES, metavar="AXIS"),
    Parameter("bvh_forward", str, None, "the BVH's forward axis (default: where the toes point)", AXES, metavar="AXIS"),
)


class SynthesizeProcessor(Processor):
    name = "synthesize"
    version = "1"
    summary = "synthesize secondary dynamics for a (new) skull motion with a synthesis model (network H)"
    reads = Reads("take", help="the take root (reads the quasistatic take below any synthesized layer)")
    writes = Writes("layer", role=SYNTHESIZED, help="the synthesized layer to write (e.g. synthesized.hop.usdc)")
    parameters = (
        Parameter("model", Path, help="the synthesis model file (network H, or an actor's linear response .response; "
                  "from train-synthesis)", metavar="MODEL"),
        Parameter("skull_motion", str, "", "BVH file, a stabilized take, or walk|run|hop|still|platform:HZ[:side|up|forward] (default: the take's own)"),
        Parameter("joint", str, "Head", "BVH joint that carries the skull"),
        *BVH_PARAMETERS,
        Parameter("seed", int, 0, "seed of a procedural motion", minimum=0),
        Parameter("backend", str, "auto", "stretch kernels", BACKENDS),
        INFERENCE_DEVICE,
    )

    def prepare(self, request: Request) -> Plan:
        from facedyn.processors.motion_source import motion_files, skull_motion

        reader, model = reader_with_model(request, self.writes.role, *SYNTHESIZES)
        params = request.params
        if params["skull_motion"]:
            translate, orient, described = skull_motion(params["skull_motion"], reader.fps, reader.frame_count, params["joint"],
                                                        params["seed"], bvh=bvh_options(params))
        elif bvh_options(params):
            raise UsageError(f"{', '.join('--bvh-' + k for k in bvh_options(params))}: BVH conventions, but no BVH --skull-motion is given")
        else:
            (translate, orient), described = reader.skull(), "the take's own"
        description = {"take": str(request.inputs[0]), "frames": reader.frame_count, "skull_motion": described}
        return Plan(description, (reader, model, params, translate, orient, described, motion_files(params["skull_motion"])))

    def run(self, plan: Plan, progress: Progress) -> LayerOutput:
        from facedyn.dynamics.synthesis import synthesize_dynamics

        reader, model, params, translate, orient, described, motion_inputs = plan.state
        stats = OffsetStats("synthesized")

        def chunks():
            progress.start("synthesize dynamics", reader.frame_count)
            for window in model_windows(reader, model):
                t, q = translate[window.lo:window.hi], orient[window.lo:window.hi]
                points, offsets = synthesize_dynamics(window.take.points, t, q, reader.fps, model,
                                                      backend=params["backend"], device=params["device"])
                yield synthesized_chunk(reader, window, points, offsets, translate, orient, stats)
                progress.advance(window.stop - window.start)
            progress.finish()

        stats.summary["skull_motion"] = described
        output = synthesized_layer(reader.time_codes, reader.head.landmarks, reader.source, [params["model"]], self.writes.role,
                                   stats.summary)
        output.inputs = list(output.inputs) + motion_inputs
        output.chunks = chunks()
        return output


def bvh_options(params: dict) -> dict:
    """The BVH conventions given on the command line (the rest are read from the file)."""
    return {key: params[f"bvh_{key}"] for key in ("units", "up", "forward") if params[f"bvh_{key}"] is not None}


