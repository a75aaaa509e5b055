"""The stabilize processor: solve the rigid skull motion of a take (papers/001).

Reads the capture (the layers below the stabilized role) and writes the stabilized layer:
the skull's translate + orient per frame, the skin in skull space, the per-frame solve
error, and the rest mesh it solved against. Composed over the capture it reproduces the
captured world-space points.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from facedyn.errors import UsageError
from facedyn.performance import BACKENDS
from facedyn.processors.base import LayerOutput, Parameter, Plan, Processor, Reads, Request, Writes, single_input
from facedyn.progress import Progress

METHODS = ("mode-pursuit", "three-point", "procrustes", "icp")


def _three_indices(text: str) -> str | None:
    if not text:
        return None
    try:
        values = [int(v) for v in text.split(",")]
    except ValueError:
        return f"expected three vertex indices i,j,k, got {text!r}"
    if len(values) != 3 or min(values) < 0 or len(set(values)) != 3:
        return f"expected three different, non-negative vertex indices i,j,k, got {text!r}"
    return None


class StabilizeProcessor(Processor):
    name = "stabilize"
    version = "1"
    summary = "solve the rigid skull motion (mode pursuit, or a three-point/Procrustes/ICP baseline)"
    reads = Reads("take", help="the take root (reads its capture, below any stabilized layer)")
    writes = Writes("layer", role="stabilized", help="the stabilized layer to write (.usdc)")
    parameters = (
        Parameter("method", str, "mode-pursuit", "mode-pursuit, or a baseline: three-point, procrustes, icp", METHODS),
        Parameter("solver", str, "fast", "mode pursuit's solver: fast, or reference (the paper's PyTorch formulation)", ("fast", "reference")),
        Parameter("init", str, "icp", "mode pursuit's initial alignment", ("identity", "three-point", "procrustes", "icp")),
        Parameter("actor", Path, None, "an actor asset (usdfacedyn actor; default: the one import --actor recorded in the "
                  "take root): its neutral and rigid region are the solve's prior, so the take lands in the actor's skull frame",
                  metavar="ACTOR"),
        Parameter("iterations", int, 12, "L-BFGS iterations per stage (the paper uses 12 or 24)", minimum=1, maximum=1000),
        Parameter("rest", str, "take", "rest mesh: the take's rest points (take), or estimated from the data (estimate)", ("take", "estimate")),
        Parameter("mask", str, "rigid", "vertices the solve uses: the take's rigid-region weights (rigid), or all", ("rigid", "all")),
        Parameter("three_point", str, "", "three vertex indices i,j,k (default: the take's eye corners and under-nose point)",
                  check=_three_indices),
        Parameter("backend", str, "auto", "fast solver's energy kernel", BACKENDS),
        Parameter("reference_fps", float, 120.0, "frame rate at which the paper's per-frame velocity widths are read",
                  above=0.0, maximum=100000.0),
    )

    def prepare(self, request: Request) -> Plan:
        from facedyn.usd.rootedit import recorded_actor
        from facedyn.usd.take import read_take_below

        path = single_input(request)
        perf, source = read_take_below(path, self.writes.role, frames=request.frames)
        params = dict(request.params)
        if params["actor"] is None:
            params["actor"] = recorded_actor(path)
        prior = None
        if params["actor"] is not None:
            perf, prior = with_actor(perf, params["actor"], path, params)
        weights, rest, three_point = _solve_inputs(perf, params)
        if prior is not None:
            weights = None  # found on this take within the actor's rigid region
        solve_weights = prior.weights if prior is not None else weights
        description = {
            "take": str(path), "frames": perf.frame_count, "points": perf.point_count, "method": params["method"],
            "solve_vertices": int(np.count_nonzero(solve_weights)) if solve_weights is not None else perf.point_count,
            "rest": f"the actor's neutral ({params['actor']})" if prior is not None else "estimated from the data" if rest is None
            else "the take's rest points",
            "three_point": three_point,
        }
        return Plan(description, (perf, source, params, weights, rest, three_point, prior))

    def run(self, plan: Plan, progress: Progress) -> LayerOutput:
        from facedyn.stabilize.api import stabilize
        from facedyn.stabilize.schedule import Schedule
        from facedyn.usd import schema
        from facedyn.usd.layers import LayerContent

        perf, source, params, weights, rest, three_point, prior = plan.state
        discovering = weights is None and (rest is None or prior is not None) and params["method"] == "mode-pursuit"
        # A plain capture (no mask, no rest) or an actor's take: the rigid mode is discovered first (from the data, or
        # checked against the actor's), then solved on the locked fine schedule.
        make = Schedule.locked if discovering else Schedule
        schedule = make(iterations=params["iterations"], reference_fps=params["reference_fps"])
        progress.start(f"stabilize ({params['method']})", 1)
        result = stabilize(
            perf.world_points(), perf.fps, method=params["method"], solver=params["solver"], rest=rest, weights=weights,
            prior=prior, init=params["init"], three_point=three_point, schedule=schedule, backend=params["backend"],
        )
        progress.finish()
        layer = LayerContent(
            frames=perf.frames, mesh_path=source.mesh_path, skull_path=source.skull_path or source.mesh_path.rsplit("/", 1)[0],
            points=result.skull_points, skull_translate=result.translate, skull_orient=result.orient,
            solve_error=result.solve_error,
            face=schema.FaceAttributes(role=self.writes.role, rest_points=result.rest.astype(np.float32), **_actor_setup(perf, params)),
            skull=schema.SkullAttributes(solver=params["method"], landmarks=perf.landmarks, reference_frame=float(perf.frames[0])),
        )
        summary = {
            "median_solve_error_cm": round(float(np.median(result.solve_error)), 5),
            "seconds": {k: round(v, 3) for k, v in result.timings.items()},
        }
        if params["actor"] is not None:
            summary["actor"] = str(params["actor"])
        if result.model is not None:
            summary["rigid_vertices"] = int(np.count_nonzero(result.model.weights >= 0.99))
        if result.knot_spacing is not None:
            summary["knot_spacing_s"] = round(result.knot_spacing, 5)
        if result.energy is not None:
            summary["final_energy"] = round(float(result.energy), 3)
            summary["backend"] = result.backend
        return LayerOutput(layer=layer, timing=source.timing, inputs=list(source.inputs), summary=summary)


def with_actor(perf, actor_path: Path, take: Path, params: dict):
    """The take with the actor's face setup, and the rigid prior to solve it with: the actor's neutral (the skull
    frame, kept as the rest) and its rigid weights (all vertices with --mask all), which the take's own data still
    checks (facedyn.stabilize.rigidity). Same topology required."""
    from facedyn.stabilize.rigidity import RigidModel
    from facedyn.usd.actor import read_actor_for

    if params["rest"] == "estimate":
        raise UsageError("an actor fixes the rest mesh (its neutral defines the skull frame); leave out --rest estimate")
    actor = read_actor_for(actor_path, perf.topology, take)
    perf = perf.with_changes(rest_points=actor.neutral, rigid_weights=actor.rigid_weights, face_vertices=actor.face_vertices,
                             skin_samples=actor.skin_samples, alignment_vertices=actor.alignment_vertices, landmarks=actor.landmarks)
    prior = None
    if params["method"] == "mode-pursuit":
        prior = RigidModel.known(actor.neutral, actor.rigid_weights if params["mask"] == "rigid" else None)
    return perf, prior


def _actor_setup(perf, params) -> dict:
    """The actor's face setup, carried into the stabilized layer so later steps read it from the take."""
    if params["actor"] is None:
        return {}
    return {"rigid_weights": perf.rigid_weights, "face_vertices": perf.face_vertices, "skin_samples": perf.skin_samples,
            "alignment_vertices": perf.alignment_vertices}


def _solve_inputs(perf, params):
    """Solve weights, rest mesh and three-point vertices from the take and the parameters."""
    from facedyn.usd.errors import TakeError

    weights = None
    if params["mask"] == "rigid" and perf.rigid_weights is not None and np.count_nonzero(perf.rigid_weights) >= 3:
        weights = perf.rigid_weights.astype(np.float64)
    rest = perf.rest_points if params["rest"] == "take" else None
    if rest is not None and len(rest) != perf.point_count:
        raise TakeError(f"the take's rest points hold {len(rest)} points for a {perf.point_count}-point mesh")
    three_point = None
    if params["three_point"]:
        three_point = tuple(int(v) for v in params["three_point"].split(","))
        if max(three_point) >= perf.point_count:
            raise UsageError(f"--three-point: vertex indices must be below {perf.point_count}, got {params['three_point']!r}")
    elif perf.alignment_vertices is not None and len(perf.alignment_vertices) == 3:
        three_point = tuple(int(v) for v in perf.alignment_vertices)
    needs_three = params["method"] == "three-point" or (params["method"] == "mode-pursuit" and params["init"] == "three-point")
    if needs_three and three_point is None:
        raise UsageError("three-point alignment needs --three-point i,j,k (the take names no eye corners / nose point)")
    return weights, rest, three_point
