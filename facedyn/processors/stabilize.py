"""The stabilize processor: solve the rigid skull motion of a take (papers/001).

Reads the capture (the layers below the stabilized role) and writes the stabilized layer:
the skull's translate + orient per frame, the skin in skull space, the per-frame solve
error, and the rest mesh it solved against. Composed over the capture it reproduces the
captured world-space points.

The take streams through in overlapping chunks (facedyn.stabilize.chunks, as mode pursuit
solves long takes in memory): each chunk is read, solved and blended into its neighbour,
and its finished frames go to the layer writer, so memory is bounded by a chunk whatever
the take's length. A take longer than one chunk is solved against one rest mesh and one
set of rigid weights for the whole take, found first on an even sample of its frames.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from facedyn.errors import UsageError
from facedyn.performance import BACKENDS, STABILIZED
from facedyn.processors.base import LayerOutput, Parameter, Plan, Processor, Reads, Request, Writes, single_input
from facedyn.progress import Progress
from facedyn.stabilize.chunks import StreamingBlend, chunk_ranges

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
    writes = Writes("layer", role=STABILIZED, help="the stabilized layer to write (.usdc)")
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
        Parameter("chunk_frames", int, 4096, "frames solved (and held in memory) at a time; longer takes go in "
                  "overlapping chunks", minimum=64, maximum=1_000_000),
        Parameter("chunk_overlap", int, 128, "frames shared by consecutive chunks (at most a quarter of --chunk-frames)",
                  minimum=8, maximum=250_000),
    )

    def prepare(self, request: Request) -> Plan:
        from facedyn.usd.frames import TakeFrames

        from facedyn.usd.rootedit import recorded_actor

        path = single_input(request)
        params = dict(request.params)
        if params["actor"] is None:
            params["actor"] = recorded_actor(path)
        if params["chunk_frames"] < 4 * params["chunk_overlap"]:
            raise UsageError(f"--chunk-frames ({params['chunk_frames']}) must be at least 4 x --chunk-overlap ({params['chunk_overlap']})")
        reader = TakeFrames(path, self.writes.role, frames=request.frames)
        perf = reader.head
        prior = None
        if params["actor"] is not None:
            perf, prior = with_actor(perf, params["actor"], path, params)
        weights, rest, three_point = _solve_inputs(perf, params)
        if prior is not None:
            weights = None  # found on this take within the actor's rigid region
        solve_weights = prior.weights if prior is not None else weights
        description = {
            "take": str(path), "frames": reader.frame_count, "points": perf.point_count, "method": params["method"],
            "solve_vertices": int(np.count_nonzero(solve_weights)) if solve_weights is not None else perf.point_count,
            "rest": f"the actor's neutral ({params['actor']})" if prior is not None else "estimated from the data" if rest is None
            else "the take's rest points",
            "three_point": three_point,
        }
        return Plan(description, (reader, perf, params, weights, rest, three_point, prior))

    def run(self, plan: Plan, progress: Progress) -> LayerOutput:
        from facedyn.stabilize.schedule import Schedule
        from facedyn.usd import schema
        from facedyn.usd.layers import LayerContent

        reader, perf, params, weights, rest, three_point, prior = plan.state
        discovering = weights is None and (rest is None or prior is not None) and params["method"] == "mode-pursuit"
        # A plain capture (no mask, no rest) or an actor's take: the rigid mode is discovered first (from the data, or
        # checked against the actor's), then solved on the locked fine schedule.
        make = Schedule.locked if discovering else Schedule
        schedule = make(iterations=params["iterations"], reference_fps=params["reference_fps"])
        source = reader.source
        layer = LayerContent(
            frames=reader.time_codes, mesh_path=source.mesh_path,
            skull_path=source.skull_path or source.mesh_path.rsplit("/", 1)[0],
            skull=schema.SkullAttributes(solver=params["method"], landmarks=perf.landmarks, reference_frame=float(reader.time_codes[0])),
        )
        summary: dict = {}
        solve = _ChunkedSolve(reader, params, weights, rest, three_point, schedule, prior)

        def chunks():
            for piece in solve.pieces(progress):
                if piece.solved_rest is not None:  # known once the first chunk is solved; written with the static values
                    layer.face = schema.FaceAttributes(role=self.writes.role, rest_points=piece.solved_rest.astype(np.float32),
                                                       **_actor_setup(perf, params))
                yield piece.content
            summary.update(solve.summary())

        # The actor is read like a layer below (--actor, or the one the take root records): an input identified by its content.
        actor = [Path(params["actor"]).resolve()] if params["actor"] is not None else []
        return LayerOutput(layer=layer, timing=source.timing, inputs=list(source.inputs) + actor, summary=summary, chunks=chunks())


@dataclass
class _Piece:
    content: object  # LayerContent of finished frames
    solved_rest: np.ndarray | None  # with the first piece: the rest mesh the take is solved against


class _ChunkedSolve:
    """The take solved chunk by chunk (facedyn.stabilize.chunks), yielding finished frames as layer chunks."""

    def __init__(self, reader, params, weights, rest, three_point, schedule, prior):
        self.reader, self.params, self.weights, self.rest, self.prior = reader, params, weights, rest, prior
        self.three_point, self.schedule = three_point, schedule
        self.ranges = chunk_ranges(reader.frame_count, params["chunk_frames"], params["chunk_overlap"])
        self.errors: list[np.ndarray] = []
        self.timings: dict[str, float] = {}
        self.energy = 0.0
        self.backend = None
        self.rigid_vertices: int | None = None  # vertices the last chunk found rigid
        self.knot_spacing: float | None = None
        self.smoothing_hz: float | None = None  # the motion's smoothing cut-off (the last chunk's)
        self.inertia = None  # a discovered rigid mode's inertia check (facedyn.stabilize.inertia), the last chunk's

    def pieces(self, progress: Progress):
        from facedyn.geometry import dualquat
        from facedyn.stabilize.api import finish, stabilize
        from facedyn.usd.layers import LayerContent

        params, reader = self.params, self.reader
        weights, rest = self.weights, self.rest
        if len(self.ranges) > 1 and self.prior is None and (rest is None or (weights is None and params["method"] == "mode-pursuit")):
            weights, rest, self.inertia = _whole_take_model(reader, params, weights, rest, self.three_point, self.schedule)
        blend = StreamingBlend(self.ranges, params["chunk_overlap"] // 2)
        progress.start(f"stabilize ({params['method']})", reader.frame_count)
        for k, (start, stop) in enumerate(self.ranges):
            world = reader.read(start, stop).world_points()
            result = stabilize(
                world, reader.fps, method=params["method"], solver=params["solver"], rest=rest, weights=weights,
                prior=self.prior, init=params["init"], three_point=self.three_point, schedule=self.schedule, backend=params["backend"],
                chunk_frames=max(stop - start, 4), chunk_overlap=0, first_frame=start,  # one chunk: this one
                transforms_only=True,  # the points once blended (below)
            )
            first, skull_to_world = blend.add(k, dualquat.from_translate_orient(result.translate, result.orient))
            rows = slice(first - start, first - start + len(skull_to_world))
            used = result.model.weights if result.model is not None else weights  # what the solve weighted
            active = np.arange(world.shape[1]) if used is None else np.flatnonzero(used > 0)
            done = finish(world[rows], dualquat.conjugate(skull_to_world), result.rest, active, result.method, None, {})
            self._account(result, done)
            frames = reader.time_codes[first:first + len(skull_to_world)]
            content = LayerContent(frames=frames, points=done.skull_points,
                                   skull_translate=done.translate, skull_orient=done.orient, solve_error=done.solve_error)
            yield _Piece(content, result.rest if k == 0 else None)
            progress.advance(len(frames))
        progress.finish()

    def _account(self, result, done) -> None:
        self.errors.append(done.solve_error)
        for key, seconds in result.timings.items():
            self.timings[key] = self.timings.get(key, 0.0) + seconds
        if result.energy is not None:
            self.energy += result.energy
            self.backend = result.backend
        if result.model is not None:
            self.rigid_vertices = int(np.count_nonzero(result.model.weights >= 0.99))
        self.knot_spacing = result.knot_spacing
        self.smoothing_hz = result.smoothing_hz
        self.inertia = result.inertia or self.inertia

    def summary(self) -> dict:
        summary = {
            "median_solve_error_cm": round(float(np.median(np.concatenate(self.errors))), 5),
            "chunks": len(self.ranges),
            "seconds": {k: round(v, 3) for k, v in self.timings.items()},
        }
        if self.backend is not None:
            summary["final_energy"] = round(float(self.energy), 3)
            summary["backend"] = self.backend
        if self.params["actor"] is not None:
            summary["actor"] = str(self.params["actor"])
        if self.rigid_vertices is not None:
            summary["rigid_vertices"] = self.rigid_vertices
        if self.knot_spacing is not None:
            summary["knot_spacing_s"] = round(self.knot_spacing, 5)
        if self.smoothing_hz is not None:
            summary["smoothing_hz"] = self.smoothing_hz
        if self.inertia is not None and self.inertia.suspect:
            summary["warning"] = (
                f"the rigid mode found is not the skull's: in its frame {self.inertia.feeding:.0%} of the other vertices "
                f"move as if they fed energy into the head's motion, which soft tissue never does ({self.inertia.absorbing:.0%} "
                "absorb it); it may be skin sliding on the skull. Stabilize with --actor (an actor made from the rig, a "
                "neutral scan, or this actor's other takes)")
        return summary


def _whole_take_model(reader, params, weights, rest, three_point, schedule):
    """One rest mesh and rigid weights for every chunk of a long take, from an even sample of its frames, and the
    discovered mode's inertia check (None where nothing was discovered).

    As stabilize() finds them on a whole take: a plain capture's rigid mode
    (facedyn.stabilize.rigidity, on its own frame sample, checked on the take's middle
    frames), a rest estimated from initially aligned frames, or for the per-frame
    baselines the first frame.
    """
    from facedyn.geometry import rigid
    from facedyn.stabilize import rest as rest_estimate
    from facedyn.stabilize.api import INIT_ICP_ITERATIONS, INIT_VERTICES, align_weighted
    from facedyn.stabilize.dropped import bridge_dropped, tracked_frames
    from facedyn.stabilize.rigidity import SAMPLE_FRAMES, discover_rigid_mode, middle_window

    count = reader.frame_count
    if params["method"] != "mode-pursuit":
        return weights, reader.read(0, 1).world_points()[0].astype(np.float64), None
    if weights is None:
        sample = _tracked(reader.read_frames(rest_estimate.sample_frames(count, SAMPLE_FRAMES)).world_points())
        middle = middle_window(count, reader.fps)
        window = reader.read(middle.start, middle.stop).world_points()
        model, check = discover_rigid_mode(sample, reader.fps, bridge_dropped(window, tracked_frames(window)))
        return model.weights, model.rest, check
    sample = _tracked(reader.read_frames(rest_estimate.sample_frames(count)).world_points())
    rot, trans = align_weighted(sample, sample[0].astype(np.float64), params["init"], weights, three_point,
                                icp_iterations=INIT_ICP_ITERATIONS, most_vertices=INIT_VERTICES)
    rest = rest_estimate.estimate_rest(rigid.apply(rot, trans, sample.astype(np.float64)), schedule.widths_pos[-1])
    return weights, rest, None


def _tracked(world: np.ndarray) -> np.ndarray:
    """The frames a tracker did not drop (whole frames of NaN)."""
    return world[np.isfinite(world).all(axis=(1, 2))]


def with_actor(perf, actor_path: Path, take: Path, params: dict):
    """The take with the actor's face setup, and the rigid prior to solve it with: the actor's neutral (the skull
    frame, kept as the rest) and its rigid weights (all vertices with --mask all), which the take's own data still
    checks (facedyn.stabilize.rigidity). Same topology required."""
    from facedyn.stabilize.rigidity import RigidModel
    from facedyn.usd.actor_asset import read_actor_for

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
