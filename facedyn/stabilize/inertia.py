"""Is the solved frame the skull's? Soft tissue absorbs the head's motion; a frame on a sliding block feeds it.

Rigidity discovery (facedyn.stabilize.rigidity) takes the largest set of vertices that stay
put together. On most faces that is the skin on the bone, but a large block of soft tissue
that no expression moves can be as still and larger: on the ICT rig as simulated, 2,777
forehead vertices slide as one block 0.38 cm against the skull (8 % of the mesh is bone
attached), and discovery locks onto the block. The data tell the two apart by inertia.

In the skull's frame every vertex is passive tissue driven by the frame's inertial load
-a: on average the load feeds it energy, which damping takes out. Its displacement x
responds to a as x = alpha a + beta da/dt (in-phase and quadrature parts, least squares
over the frames, band-passed to the head's motion, BAND_HZ) with beta > 0, at every
frequency: <-a . dx/dt> = <x . da/dt> > 0 is the power the load feeds in. In a frame
carried by a sliding block the bone appears to move by minus the block's response, with
beta < 0: it would feed energy into the head's motion, which no tissue does. So the check
counts the vertices whose motion the acceleration explains (R^2 >= EXPLAINED: inertia,
not an expression that happens to move with the head) and whose quadrature part is at
least SIGNED_SHARE of their response, feeding or absorbing, and calls the frame suspect
when more than FEEDING of the checked vertices feed.

Measured on the ICT rig's takes of benchmarks/bench_stabilize_plain.py (others: the
vertices left out of the mode): in the true skull frame 58-91 % absorb and none feed; in
the discovered block's frame 20-73 % feed (the 9 Hz platform too, where an in-phase test
reads noise). Synthetic takes without dynamics (facedyn.stabilize.synthetic): no vertex
passes EXPLAINED, nothing is flagged.

The in-phase part tells which vertex is stiffest: in a block's frame the bone leads most
(alpha largest, the head's motion being mostly below the block's resonance), which
skull_seed uses to find it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facedyn.geometry import quaternion
from facedyn.stabilize.bandpass import butter_bandpass, filtfilt
from facedyn.stabilize.rest import sample_frames

BAND_HZ = (0.7, 15.0)  # the head's motion: walking and running (1-5 Hz) to platforms (up to 15 Hz); top <= fps / 4
EXPLAINED = 0.5  # R^2 of the response to acceleration at which a vertex's motion counts as inertia
SIGNED_SHARE = 0.1  # |quadrature| / response at which a vertex feeds or absorbs
FEEDING = 0.1  # more than this fraction of the checked vertices feeding: the frame is not the skull's
MOST_VERTICES = 512  # left-out vertices the check looks at, evenly strided
LEAD_HZ = 15.0  # skull_seed: a vertex leads when it moves in phase with the load as a spring of this frequency or stiffer
SEED_SHARE = 0.8  # skull_seed: vertices leading within this share of the strongest lead
MIN_SECONDS = 1.0


@dataclass(frozen=True)
class InertiaCheck:
    """Fractions of the checked vertices that feed energy into the head's motion and that absorb it;
    suspect: more than FEEDING feed."""

    feeding: float
    absorbing: float
    vertices: int

    @property
    def suspect(self) -> bool:
        return self.feeding > FEEDING


@dataclass(frozen=True)
class Response:
    """Per vertex: in-phase gain alpha (s^2), quadrature share in [-1, 1] (> 0 absorbs), R^2 of the fit."""

    in_phase: np.ndarray
    quadrature_share: np.ndarray
    explained: np.ndarray


def check_frame(world: np.ndarray, translate: np.ndarray, orient: np.ndarray, rest: np.ndarray,
                vertices: np.ndarray, fps: float) -> InertiaCheck | None:
    """How the vertices (indices, the soft tissue left out of the rigid mode) move in the solved frame.

    world (F, N, 3), dropped frames bridged (facedyn.stabilize.dropped); translate (F, 3) and orient (F, 4, wxyz) the frame
    to world; rest (N, 3). None where the take cannot tell: shorter than MIN_SECONDS, fps
    too low for the band to span two octaves, or fewer than 3 vertices.
    """
    if not _can_tell(len(world), fps) or len(vertices) < 3:
        return None
    used = vertices[sample_frames(len(vertices), MOST_VERTICES)]  # evenly spaced indices
    response = _vertex_response(world, translate, orient, rest, used, fps)
    inertial = response.explained >= EXPLAINED
    share = response.quadrature_share
    return InertiaCheck(float(np.mean(inertial & (share < -SIGNED_SHARE))), float(np.mean(inertial & (share > SIGNED_SHARE))),
                        len(used))


def skull_seed(world: np.ndarray, translate: np.ndarray, orient: np.ndarray, rest: np.ndarray, fps: float) -> np.ndarray | None:
    """(N,) bool: the vertices that lead a suspect frame the most, where to look for the skull instead.

    In a frame carried by a sliding block, the bone appears to move by minus the block's
    lag, and tissue stiffer than the block leads it by less: below the block's resonance
    the bone is what leads most. So the seed is every inertial vertex (as check_frame
    counts them) whose in-phase gain is within SEED_SHARE of the strongest lead (the 99th
    percentile of their gains, not the maximum, which a noisy vertex can set). Measured on
    the ICT rig's discovered frames (2 s takes): 1,081-1,183 vertices, holding 906-910 of
    its 910 bone vertices on walking, running, hopping and the 9 Hz platform. None where
    the take cannot tell (as check_frame) or nothing leads.
    """
    if not _can_tell(len(world), fps):
        return None
    response = _vertex_response(world, translate, orient, rest, np.arange(world.shape[1]), fps)
    inertial = response.explained >= EXPLAINED
    if np.count_nonzero(inertial) < 3:
        return None
    strongest = float(np.percentile(response.in_phase[inertial], 99.0))
    if strongest <= (2.0 * np.pi * LEAD_HZ) ** -2:
        return None
    return inertial & (response.in_phase >= SEED_SHARE * strongest)


def _vertex_response(world: np.ndarray, translate: np.ndarray, orient: np.ndarray, rest: np.ndarray,
                     vertices: np.ndarray, fps: float, block: int = 1024) -> Response:
    """Each vertex's displacement from its rest fitted as alpha a + beta da/dt, a the frame's acceleration there,
    both in the frame and band-passed to BAND_HZ (least squares over the frames and axes), a block of vertices at a time.

    The acceleration at a rest point p is R(t)^T (R''(t) p + T''(t)) = A(t) p + b(t), linear in p,
    and so are the band-pass and the derivative: the frame's twelve channels of A and b go
    through the filter beside the vertices' displacements, not three more channels per vertex."""
    rot = quaternion.to_matrix(orient)
    band = butter_bandpass(BAND_HZ[0], min(BAND_HZ[1], fps / 4.0), fps)
    second = np.gradient(np.gradient(np.concatenate([rot.reshape(-1, 9), translate], axis=1), axis=0), axis=0) * (fps * fps)
    frame = np.concatenate([np.einsum("fji,fjk->fik", rot, second[:, :9].reshape(-1, 3, 3)).reshape(-1, 9),
                            np.einsum("fji,fj->fi", rot, second[:, 9:])], axis=1)  # A(t), b(t) in the frame
    fields = np.empty((3, len(vertices)))
    for start in range(0, len(vertices), block):
        used = vertices[start:start + block]
        points = np.asarray(rest, dtype=np.float64)[used]
        displacement = np.einsum("fji,fnj->fni", rot, world[:, used] - translate[:, None]) - points
        filtered = filtfilt(band, np.concatenate([displacement.reshape(len(rot), -1), frame], axis=1))  # one pass for both
        channels = filtered.shape[1] - frame.shape[1]
        displacement, a_b = filtered[:, :channels].reshape(displacement.shape), filtered[:, channels:]
        acceleration, jerk = (np.einsum("fij,nj->fni", f[:, :9].reshape(-1, 3, 3), points) + f[:, None, 9:]
                              for f in (a_b, np.gradient(a_b, axis=0) * fps))
        fields[:, start:start + len(used)] = _fit(displacement, acceleration, jerk)
    return Response(*fields)


def _fit(x: np.ndarray, a: np.ndarray, jerk: np.ndarray) -> np.ndarray:
    """(3, n): alpha, the signed quadrature share and R^2 of x ~ alpha a + beta jerk, per vertex, each (F, n, 3)."""
    def dot(u, v):
        return np.sum(u * v, axis=(0, 2))

    aa, jj, aj, xa, xj = dot(a, a), dot(jerk, jerk), dot(a, jerk), dot(x, a), dot(x, jerk)
    det = np.maximum(aa * jj - aj * aj, 1e-30)
    alpha, beta = (xa * jj - xj * aj) / det, (xj * aa - xa * aj) / det
    residual = x - alpha[None, :, None] * a - beta[None, :, None] * jerk
    explained = 1.0 - dot(residual, residual) / np.maximum(dot(x, x), 1e-24)
    in_phase, quadrature = alpha * np.sqrt(aa), beta * np.sqrt(jj)
    share = quadrature / np.maximum(np.hypot(in_phase, quadrature), 1e-30)
    return np.stack([alpha, share, explained])


def _can_tell(frames: int, fps: float) -> bool:
    """Long enough (MIN_SECONDS), and fast enough that the band spans two octaves, for the head's motion to show."""
    return frames >= MIN_SECONDS * fps and fps / 4.0 >= 4.0 * BAND_HZ[0]
