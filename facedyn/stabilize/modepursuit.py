"""Mode pursuit (papers/001): the continuation over widths and spline levels.

The solve runs in "problem units": world points minus the chunk's centroid, rest minus
its centroid, both divided by the rest's RMS radius. SDLB commutes with fixed rigid maps
on either side, so this is the same family of motions as in world units, but rotation
and translation parameters get comparable scales, which L-BFGS needs in few iterations.

Long takes are cut into overlapping chunks (facedyn.stabilize.chunks), each solved on
its own with its own spline through every stage (knotted on the take's one grid, so that
a chunk's spline space is the whole take's away from its ends), and their transforms are
blended in the overlaps; memory is bounded by one chunk's arrays.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from facedyn.geometry import bspline, dualquat, quaternion, sdlb
from facedyn.stabilize import chunks as chunking
from facedyn.stabilize.energy import NumpyEnergy
from facedyn.stabilize.schedule import Schedule
from facedyn.stabilize.velocity import derivative_operator


@dataclass
class StageRecord:
    index: int
    width_pos: float  # cm
    width_vel: float  # cm/s
    controls: int = 0  # control dual quaternions, all chunks
    energy: float = 0.0  # the solver's final energy of the stage, summed over chunks
    evaluations: int = 0  # energy and gradient evaluations, all chunks
    seconds: float = 0.0


@dataclass
class ModePursuitOutput:
    world_to_skull: np.ndarray  # (F, 8) unit dual quaternions
    energy: float  # final energy at the last stage's widths (NumPy evaluation, whatever the solver)
    history: list[StageRecord]
    timings: dict[str, float]


class _Units:
    """world <-> problem units: x' = (x - center) / scale (world side), (s - rest_center) / scale."""

    def __init__(self, rest_center: np.ndarray, scale: float):
        self.rest_center = rest_center
        self.scale = scale

    def points(self, world: np.ndarray, center: np.ndarray) -> np.ndarray:
        """(F, Na, 3) world points -> (F, 3, Na) float32 problem points."""
        x = np.subtract(world, center.astype(world.dtype), dtype=np.float32)
        x *= np.float32(1.0 / self.scale)
        return np.ascontiguousarray(x.transpose(0, 2, 1))

    def rest(self, rest: np.ndarray) -> np.ndarray:
        """(Na, 3) rest in skull space -> (3, Na) problem units."""
        return ((rest - self.rest_center) / self.scale).T

    def to_problem(self, rot: np.ndarray, trans: np.ndarray, center: np.ndarray) -> np.ndarray:
        """World-to-skull (R, t) -> problem dual quaternions: t' = (R c + t - c_rest) / L."""
        t = (np.einsum("fij,j->fi", rot, center) + trans - self.rest_center) / self.scale
        return dualquat.from_translate_orient(t, quaternion.from_matrix(rot))

    def to_world(self, dq: np.ndarray, center: np.ndarray) -> np.ndarray:
        """Problem dual quaternions -> world-to-skull: t = L t' - R c + c_rest."""
        rot, t = dualquat.to_rotation_translation(dq)
        trans = self.scale * t - np.einsum("fij,j->fi", rot, center) + self.rest_center
        return dualquat.from_translate_orient(trans, dq[:, :4])


def mode_pursuit(
    world: np.ndarray,
    fps: float,
    active: np.ndarray,
    weights: np.ndarray | None,
    rest: np.ndarray,
    init_rot: np.ndarray,
    init_trans: np.ndarray,
    schedule: Schedule,
    solver,
    chunk_frames: int,
    chunk_overlap: int,
    first_frame: int = 0,
) -> ModePursuitOutput:
    """Solve world-to-skull transforms for world (F, N, 3) from initial per-frame maps.

    active: vertex indices in the energy; weights: their weights (None: all 1); rest:
    (Na, 3) rest of the active vertices in skull space; init_rot, init_trans: per-frame
    world-to-skull maps that the first spline is fitted to; first_frame: where world
    starts in its take (a chunk of a streamed take), which places the spline's knots.
    """
    timings = {"prepare": 0.0, "solve": 0.0, "energy": 0.0}
    rest = np.asarray(rest, dtype=np.float64)
    rest_center = rest.mean(axis=0)
    scale = float(np.sqrt(np.mean(np.sum((rest - rest_center) ** 2, axis=1))))
    if not scale > 0:
        raise ValueError("the rest mesh has no extent: mode pursuit needs several distinct active vertices")
    units = _Units(rest_center, scale)
    stages = schedule.stages()
    history = [StageRecord(s.index, s.width_pos, s.width_vel) for s in stages]
    ranges = chunking.chunk_ranges(world.shape[0], chunk_frames, chunk_overlap)
    blend = chunking.blend_weights(ranges, chunk_overlap // 2)
    total = np.zeros((world.shape[0], 8))
    energy = 0.0
    for (start, stop), blend_weight in zip(ranges, blend):
        t0 = time.perf_counter()
        frames = stop - start
        center = world[start:stop, active].mean(axis=(0, 1), dtype=np.float64)
        points = units.points(world[start:stop, active], center)
        velocity = derivative_operator(frames, fps)
        knots = schedule.coarse_knots(first_frame + start, frames, fps)
        x = np.arange(first_frame + start, first_frame + stop, dtype=np.float64)
        initial = units.to_problem(init_rot[start:stop], init_trans[start:stop], center)
        controls = sdlb.fit_controls(bspline.basis(knots, x), initial)
        evaluator = solver.bind(points, units.rest(rest), velocity, weights)
        memo: dict = {}
        timings["prepare"] += time.perf_counter() - t0
        for stage, record in zip(stages, history):
            t_stage = time.perf_counter()
            if stage.refine:
                knots, controls = bspline.refine_midpoints(knots, sdlb.align_signs(controls)[0])
            wp, wv = stage.width_pos / scale, stage.width_vel / scale
            basis = bspline.basis(knots, x)
            controls, value, count = solver.minimize(evaluator, basis, controls, wp, wv, schedule.iterations, memo)
            record.controls += len(controls)
            record.energy += value
            record.evaluations += count
            record.seconds += time.perf_counter() - t_stage
            timings["solve"] += time.perf_counter() - t_stage
        t0 = time.perf_counter()
        del evaluator  # one chunk's buffers at a time
        dq = sdlb.blend(basis, controls)
        if getattr(solver, "energy_is_numpy", False):
            energy += value  # the last stage's final value is already the yardstick's
        else:
            motion = dualquat.to_rotation_translation(dq)
            common = NumpyEnergy(points, units.rest(rest), velocity, weights)  # the same yardstick for every solver
            common.rebase(*motion)
            e_pos, e_vel, _, _ = common(*motion, wp, wv, gradient=False)
            energy += e_pos + e_vel
        timings["energy"] += time.perf_counter() - t0
        dq = units.to_world(dq, center)
        current = total[start:stop]
        dq[np.sum(current[:, :4] * dq[:, :4], axis=1) < 0] *= -1.0  # same hemisphere as the previous chunk
        current += blend_weight[:, None] * dq
    return ModePursuitOutput(dualquat.make_continuous(dualquat.normalize(total)), energy, history, timings)
