"""stabilize(): one entry point for mode pursuit and the per-frame baselines.

Input is the tracked mesh in world space (F, N, 3); output is the skull transform per
frame in facedyn's convention (skull -> world: world = R(orient) skull + translate),
the stabilized (skull-space) points, the rest mesh, a per-frame solve error, and, for
mode pursuit, the energy per stage, timings, and the rigid model it solved with (weights
and rest, discovered from the data unless given: facedyn.stabilize.rigidity), which an
actor keeps so that its later takes start from it.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from facedyn.geometry import dualquat, quaternion, rigid
from facedyn.stabilize import baselines
from facedyn.stabilize import rest as rest_estimate
from facedyn.stabilize.dropped import bridge_dropped, tracked_frames
from facedyn.stabilize.fast import FastSolver
from facedyn.stabilize.inertia import InertiaCheck, check_frame
from facedyn.stabilize.modepursuit import StageRecord, mode_pursuit
from facedyn.stabilize.rigidity import FIT_VERTICES, ICP_ITERATIONS, RigidModel, discover, estimate_rigidity
from facedyn.stabilize.schedule import Schedule
from facedyn.stabilize.smoothing import smooth_skull_motion

METHODS = ("three-point", "procrustes", "icp", "mode-pursuit")
SOLVERS = ("fast", "reference")
# the initial ICP's iterations, and the vertices it fits on at most (as accurate as all 2,590 of a face's rigid
# region): the rigidity discovery's, whose fit of the frames it checks is then the initialization (_reuse_fit)
INIT_ICP_ITERATIONS, INIT_VERTICES = ICP_ITERATIONS, FIT_VERTICES


@dataclass
class StabilizeResult:
    translate: np.ndarray  # (F, 3) skull -> world
    orient: np.ndarray  # (F, 4) wxyz, skull -> world
    skull_points: np.ndarray | None  # (F, N, 3) float32, T(t)^-1 world (None: asked for transforms only)
    rest: np.ndarray  # (N, 3) rest mesh in skull space
    solve_error: np.ndarray | None  # (F,) float32: median distance (cm) of active vertices to rest (None: as above)
    method: str
    solver: str | None = None
    backend: str | None = None  # the fast solver's energy backend: "numpy" or "opencl"
    energy: float | None = None  # mode pursuit: final energy at the last widths
    history: list[StageRecord] = field(default_factory=list)
    timings: dict[str, float] = field(default_factory=dict)
    model: RigidModel | None = None  # mode pursuit: the weights and rest it solved with (an actor's prior)
    tracked: np.ndarray | None = None  # (F,) bool: False on dropped frames (bridged, facedyn.stabilize.dropped)
    knot_spacing: float | None = None  # mode pursuit: seconds between the final spline's knots
    smoothing_hz: float | None = None  # mode pursuit: the cut-off of the motion's smoothing (facedyn.stabilize.smoothing)
    inertia: InertiaCheck | None = None  # discovered weights: whether the frame lags like the skull's (suspect: it leads)


def _check_inputs(world, fps, rest, weights):
    world = np.asarray(world)
    if world.ndim != 3 or world.shape[2] != 3:
        raise ValueError(f"world_points must be (frames, N, 3), got {world.shape}")
    if world.shape[0] < 1 or world.shape[1] < 3:
        raise ValueError(f"need at least 1 frame and 3 points, got {world.shape}")
    if not np.issubdtype(world.dtype, np.floating):
        world = world.astype(np.float64)
    for f in range(0, len(world), 4096):
        block = world[f : f + 4096]
        finite = np.isfinite(block)
        if not (finite.all() or np.all(finite.any(axis=(1, 2)) == finite.all(axis=(1, 2)))):
            raise ValueError("world_points contain NaN or infinite values (only whole frames may be NaN: dropped)")
        if np.isinf(block).any():
            raise ValueError("world_points contain infinite values")
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"fps must be a positive number, got {fps}")
    n = world.shape[1]
    if rest is not None:
        rest = np.asarray(rest, dtype=np.float64)
        if rest.shape != (n, 3):
            raise ValueError(f"rest must be ({n}, 3) like one frame of world_points, got {rest.shape}")
    if weights is not None:
        weights = np.asarray(weights, dtype=np.float64)
        if weights.shape != (n,):
            raise ValueError(f"weights must be ({n},), one per vertex, got {weights.shape}")
        if np.any(weights < 0) or not np.all(np.isfinite(weights)):
            raise ValueError("weights must be finite and non-negative")
        if np.count_nonzero(weights) < 3:
            raise ValueError("at least 3 vertices need a positive weight")
    return world, rest, weights


def stabilize(
    world_points: np.ndarray,
    fps: float,
    method: str = "mode-pursuit",
    solver: str = "fast",
    rest: np.ndarray | None = None,
    weights: np.ndarray | None = None,
    *,
    prior: RigidModel | None = None,
    valid: np.ndarray | None = None,
    init: str = "icp",
    three_point: tuple[int, int, int] | None = None,
    schedule: Schedule | None = None,
    backend: str = "auto",
    chunk_frames: int = 4096,
    chunk_overlap: int = 128,
    reference_frame: int = 0,
    first_frame: int = 0,
    transforms_only: bool = False,
) -> StabilizeResult:
    """Solve the rigid skull motion of a tracked face mesh.

    world_points: (F, N, 3) in world space (cm); fps: capture rate.
    method: "mode-pursuit" (papers/001) or a per-frame baseline "three-point",
    "procrustes", "icp" (robust, Geman-McClure).
    solver: mode pursuit's "fast" (analytic gradients, float32, fixed-iteration L-BFGS;
    backend "opencl", "numpy" or "auto": OpenCL where a device builds the kernels) or
    "reference" (PyTorch autograd + torch.optim.LBFGS, the paper's formulation).
    rest: (N, 3) rest mesh in skull space; None estimates it from the data (per-vertex
    mode of the aligned frames, facedyn.stabilize.rest); baselines use frame
    ``reference_frame`` instead.
    weights: (N,) per-vertex weights (0 excludes a vertex, e.g. a rigid-region mask);
    None with no rest (a plain capture) or with a prior: mode pursuit discovers them from
    the data (facedyn.stabilize.rigidity); otherwise every vertex counts.
    prior: a RigidModel found on the actor's other takes (``result.model``, merged): the
    take is solved in its skull frame (its rest), on the vertices rigid there and here.
    valid: (F,) bool, False on frames the tracker dropped; frames that are all NaN or an
    exact repeat of the frame before count as dropped too. They are bridged by
    interpolation (facedyn.stabilize.dropped); their skull points stay what came in.
    init: mode pursuit's initialization: "identity", "three-point", "procrustes", "icp".
    three_point: vertex indices for three-point alignment (method or init).
    schedule: widths, iterations per stage, spline levels (facedyn.stabilize.schedule);
    None: ``Schedule.locked()`` when the weights were discovered or came with a prior,
    the paper's full continuation ``Schedule()`` otherwise. A schedule with no knot
    spacing (``Schedule.locked()``) gets a knot per frame, and the solved motion is then
    smoothed with a cut-off chosen for the take (facedyn.stabilize.smoothing).
    chunk_frames, chunk_overlap: takes longer than chunk_frames are solved in
    overlapping chunks with bounded memory, blended in the overlaps.
    first_frame: where world_points start in a longer take (a streamed chunk of it):
    the spline's knots lie on the take's grid (Schedule.coarse_knots).
    transforms_only: leave out skull_points and solve_error (a streamed chunk's are made
    once its transforms are blended with the next chunk's).
    """
    t_total = time.perf_counter()
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {SOLVERS}, got {solver!r}")
    if init not in baselines.METHODS:
        raise ValueError(f"init must be one of {baselines.METHODS}, got {init!r}")
    captured, rest, weights = _check_inputs(world_points, fps, rest, weights)
    frames, n, _ = captured.shape
    if not -frames <= reference_frame < frames:
        raise ValueError(f"reference_frame {reference_frame} out of range for {frames} frames")
    if prior is not None and prior.weights.shape != (n,):
        raise ValueError(f"the prior rigid model has {len(prior.weights)} vertices, the take {n}")
    tracked = tracked_frames(captured, valid)
    world = bridge_dropped(captured, tracked)
    timings: dict[str, float] = {}

    t0 = time.perf_counter()
    model = discovery = None
    if method == "mode-pursuit" and weights is None and (rest is None or prior is not None):
        if prior is None:
            discovery = discover(world, fps)  # the solved frame is checked again below where the discovery's check cannot stand for it
            model = discovery.model
        else:
            model = estimate_rigidity(world, prior)
        weights = model.weights
        rest = model.rest if rest is None else rest
    elif prior is not None:
        weights = prior.weights if weights is None else weights
        rest = prior.rest if rest is None else rest
    timings["rigidity"] = time.perf_counter() - t0
    if schedule is None:
        schedule = Schedule.locked() if model is not None or prior is not None else Schedule()
    active = np.arange(n) if weights is None else np.flatnonzero(weights > 0)
    target = rest if rest is not None else world[reference_frame].astype(np.float64)

    def initial_alignment(target):
        # an initialization only: the spline fit and the first (widest) stage absorb what
        # further reweighting would refine
        return align_weighted(world, target, init, weights, three_point, icp_iterations=INIT_ICP_ITERATIONS,
                              most_vertices=INIT_VERTICES)

    t0 = time.perf_counter()
    if method == "mode-pursuit" and discovery is not None and init == "icp":
        rot, trans = _reuse_fit(discovery, frames, lambda frames: align_weighted(
            world[frames], target, init, weights, icp_iterations=INIT_ICP_ITERATIONS, most_vertices=INIT_VERTICES))
    elif method == "mode-pursuit":
        rot, trans = initial_alignment(target)
    else:
        rot, trans = align_weighted(world, target, method, weights, three_point)
    timings["init"] = time.perf_counter() - t0
    if method != "mode-pursuit":
        world_to_skull = dualquat.from_translate_orient(trans, quaternion.from_matrix(rot))
        result = finish(captured, world_to_skull, target, active, method, None, timings, not transforms_only)
        result.tracked = tracked
        result.timings["total"] = time.perf_counter() - t_total
        return result

    if rest is None:
        t0 = time.perf_counter()
        rest = _estimate_rest(world, rot, trans, schedule.widths_pos[-1])
        rot, trans = initial_alignment(rest)  # as each chunk of a streamed take starts: aligned to the rest
        timings["init"] += time.perf_counter() - t0
    smooth_per_take = schedule.knot_spacing is None  # a knot per frame, then the take's smoothness prior
    if smooth_per_take:
        schedule = replace(schedule, knot_spacing=1.0 / fps)
    if solver == "fast":
        stage_solver = FastSolver(backend)
    else:
        from facedyn.stabilize.reference import ReferenceSolver  # PyTorch: imported only when asked for

        stage_solver = ReferenceSolver()
    uniform = weights is None or np.all(weights[active] == 1.0)
    out = mode_pursuit(
        world,
        fps,
        active,
        None if uniform else weights[active],
        rest[active],
        rot,
        trans,
        schedule,
        stage_solver,
        chunk_frames,
        chunk_overlap,
        first_frame,
    )
    timings.update(out.timings)
    world_to_skull, cutoff = out.world_to_skull, None
    if smooth_per_take:
        t0 = time.perf_counter()
        world_to_skull, cutoff = smooth_skull_motion(world_to_skull, fps, rest[active], tracked)
        timings["smoothing"] = time.perf_counter() - t0
    result = finish(captured, world_to_skull, rest, active, method, solver, timings, not transforms_only)
    final_weights = np.ones(n) if weights is None else weights
    spread = model.spread if model is not None else np.zeros(n)
    result.model = RigidModel(final_weights, rest, spread, model.noise_cm if model is not None else 0.0)
    if model is not None and prior is None:
        result.inertia = _solved_frame_check(discovery, world, result, rest, weights, fps)
    result.tracked = tracked
    result.energy = out.energy
    result.knot_spacing = schedule.knot_spacing
    result.smoothing_hz = cutoff
    result.backend = getattr(stage_solver, "used_backend", None)
    result.history = out.history
    result.timings["total"] = time.perf_counter() - t_total
    return result


def _solved_frame_check(discovery, world: np.ndarray, result: StabilizeResult, rest: np.ndarray, weights: np.ndarray,
                        fps: float) -> InertiaCheck | None:
    """The inertia check of the solved frame: the discovery's own where it checked every frame of the take and
    found the mode passive, since the solve refines that same frame (on seven plain captures, 120-651 frames, the
    two checks' feeding fractions were equal and their absorbing ones within 0.06; the check again cost 0.17 s of
    the 651-frame command's 1.6 s); checked again where the discovery saw only the take's middle or a suspect frame."""
    if discovery is not None and discovery.check is not None and not discovery.check.suspect and discovery.frames == slice(0, len(world)):
        return discovery.check
    return check_frame(world, result.translate, result.orient, rest, np.flatnonzero(weights == 0), fps)


def _reuse_fit(discovery, count: int, align) -> tuple[np.ndarray, np.ndarray]:
    """The initial alignment of all `count` frames, reusing the discovery's fit of the frames it checked (the same
    robust ICP on the same vertices to the same rest: rigidity.Discovery); align(frames) fits the frames outside."""
    rot, trans = np.empty((count, 3, 3)), np.empty((count, 3))
    inside = discovery.frames
    rot[inside], trans[inside] = discovery.rot, discovery.trans
    for outside in (slice(0, inside.start), slice(inside.stop, count)):
        if outside.stop > outside.start:
            rot[outside], trans[outside] = align(outside)
    return rot, trans


def align_weighted(world, target, method, weights, three_point=None, most_vertices=None, **options):
    """baselines.align_frames, fitting Procrustes and ICP on the vertices of positive weight only: the others add
    nothing to the fit but would cost as much as the rigid region (a third of a face mesh or more). most_vertices:
    fit on at most that many of them, evenly strided (an initialization need not see every vertex)."""
    if method not in ("procrustes", "icp"):
        return baselines.align_frames(world, target, method, weights, three_point, **options)
    used = np.arange(world.shape[1]) if weights is None else np.flatnonzero(weights > 0)
    if most_vertices is not None and len(used) > most_vertices:
        used = used[rest_estimate.sample_frames(len(used), most_vertices)]  # evenly spaced indices
    if len(used) == world.shape[1]:
        return baselines.align_frames(world, target, method, weights, **options)
    return baselines.align_frames(world[:, used], target[used], method, None if weights is None else weights[used], **options)


def _estimate_rest(world: np.ndarray, rot: np.ndarray, trans: np.ndarray, width: float, block: int = 512) -> np.ndarray:
    """The rest mesh from initially aligned frames (sampled), a block of vertices at a time."""
    sample = rest_estimate.sample_frames(len(world))
    rest = np.empty(world.shape[1:])
    for v in range(0, world.shape[1], block):
        aligned = rigid.apply(rot[sample], trans[sample], world[sample, v : v + block].astype(np.float64))
        rest[v : v + block] = rest_estimate.estimate_rest(aligned, width)
    return rest


def finish(world, world_to_skull, rest, active, method, solver, timings, points: bool = True) -> StabilizeResult:
    """Skull transforms, skull-space points, rest and per-frame error from world-to-skull maps (with points=False:
    the transforms and rest only)."""
    t0 = time.perf_counter()
    skull_to_world = dualquat.conjugate(world_to_skull)
    translate, orient = dualquat.to_translate_orient(skull_to_world)
    rest = np.asarray(rest, dtype=np.float64)
    if not points:
        timings["output"] = time.perf_counter() - t0
        return StabilizeResult(translate, orient, None, rest, None, method, solver, timings=timings)
    frames, n, _ = world.shape
    rot, trans = dualquat.to_rotation_translation(world_to_skull)
    skull = np.empty((frames, n, 3), dtype=np.float32)
    for start in range(0, frames, 1024):
        sl = slice(start, start + 1024)
        skull[sl] = rigid.apply(rot[sl], trans[sl], world[sl].astype(np.float64))
    error = np.empty(frames, dtype=np.float32)
    for start in range(0, frames, 1024):
        sl = slice(start, start + 1024)
        d = skull[sl][:, active] - rest[active].astype(np.float32)
        error[sl] = np.sqrt(np.median(np.einsum("fni,fni->fn", d, d), axis=1))
    timings["output"] = time.perf_counter() - t0
    return StabilizeResult(translate, orient, skull, rest, error, method, solver, timings=timings)
