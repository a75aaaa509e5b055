"""How densely the skull's spline is knotted, chosen per take from its own motion and noise.

The knot spacing is the solve's smoothness prior, and no one spacing suits every take:
knots every 1/40 s smooth the tracking noise out of a walk's or a dialog's skull
accelerations (the networks' input), but follow neither a run's foot strikes at 60 fps
(accelerations 4.8 % of their RMS off) nor a 9 Hz platform (7.4 %); knotted every frame,
the spline follows both and passes the noise of a slow take through.

The choice is generalized cross-validation (GCV) of a spline fit to the initial per-frame
alignment (which carries the take's motion and its noise): the residual of each candidate
spacing, at a handful of probe points around the rigid region, weighed against its degrees
of freedom, with no noise level to know. GCV cannot judge a spline knotted every frame (it
interpolates), so when its score still falls at the finest candidate it can judge, the
motion is faster than any smoothing keeps and the knots go on every frame.
"""
from __future__ import annotations

import numpy as np

from facedyn.geometry import bspline, dualquat, quaternion, sdlb

FRAMES_PER_KNOT = (8.0, 6.0, 4.0, 3.0, 2.0, 1.5, 1.25)  # the candidates GCV judges, coarsest first
EVERY_FRAME = 1.0


def choose_knot_spacing(rot: np.ndarray, trans: np.ndarray, fps: float, rest: np.ndarray,
                        candidates: tuple[float, ...] = FRAMES_PER_KNOT) -> float:
    """Seconds between the spline's knots for a take, by GCV on its initial alignment.

    rot, trans: (F, 3, 3), (F, 3) per-frame world-to-skull maps; rest: (Na, 3) the rigid
    region's rest in skull space (where the probe points go: its centre +- its RMS radius
    along each axis).
    """
    frames = len(rot)
    judged = [c for c in candidates if c > EVERY_FRAME and (frames - 1) / c >= 1]
    if frames < 4 or not judged:
        return EVERY_FRAME / fps
    center = np.asarray(rest, dtype=np.float64).mean(axis=0)
    radius = float(np.sqrt(np.mean(np.sum((rest - center) ** 2, axis=1))))
    probes = radius * np.concatenate([np.eye(3), -np.eye(3)])  # skull space, about the centre
    # world-to-skull maps between centred coordinates (the rest's centre, and where it lands in the world on
    # average), as mode pursuit fits them, so that the blend does not turn about a far origin
    world_center = np.einsum("fji,fj->i", rot, center - trans) / frames
    shift = np.einsum("fij,j->fi", rot, world_center) + trans - center
    dq = dualquat.make_continuous(dualquat.from_translate_orient(shift, quaternion.from_matrix(rot)))
    seen = _probe_paths(dq, probes)
    x = np.arange(frames, dtype=np.float64)
    scores = []
    for frames_per_knot in judged:
        basis = bspline.basis(bspline.clamped_uniform_knots(int(np.ceil((frames - 1) / frames_per_knot)), 0.0, frames - 1), x)
        fitted = _probe_paths(dualquat.normalize(sdlb.blend(basis, sdlb.fit_controls(basis, dq))), probes)
        free = 1.0 - basis.shape[1] / frames
        scores.append(np.sum((fitted - seen) ** 2) / (frames * free * free) if free > 0 else np.inf)
    best = int(np.argmin(scores))
    return (EVERY_FRAME if best == len(judged) - 1 else judged[best]) / fps


def _probe_paths(world_to_skull: np.ndarray, probes: np.ndarray) -> np.ndarray:
    """(F, P, 3): where each skull-space probe point sits in (centred) world space per frame."""
    rot, trans = dualquat.to_rotation_translation(world_to_skull)
    return np.einsum("fji,fpj->fpi", rot, probes[None] - trans[:, None])
