"""Is the solved frame the skull's? Soft tissue lags the skull; a frame on a sliding block leads it.

Rigidity discovery (facedyn.stabilize.rigidity) takes the largest set of vertices that stay
put together. On most faces that is the skin on the bone, but a large block of soft tissue
that no expression moves can be as still and larger: on the ICT rig as simulated, 2,777
forehead vertices slide as one block 0.38 cm against the skull (8 % of the mesh is bone
attached), and discovery locks onto the block. The data tell the two apart by inertia.
In the skull's frame, tissue on a spring lags the head: below its natural frequency f its
displacement is about -a / (2 pi f)^2 for the frame's acceleration a (a negative gain). In
a frame carried by a sliding block the bone is what appears to move, by minus the block's
lag: a positive gain (tissue softer than the block still lags it). So the check regresses
each left-out vertex's displacement from its rest on the frame's acceleration there,
band-passed to the head's own motion (BAND_HZ: below the soft tissue's resonance, above
slow expression changes and gravity's sag), counts the vertices that lead or lag by a
gain of 1/(2 pi GAIN_HZ)^2, and calls the frame suspect when more than LEADING of them
lead. Measured on the takes of benchmarks/bench_stabilize_plain.py: ICT discovered frames
25-50 % lead, 0-0.4 % lag; the built-in face's discovered frames 0-1.4 % lead, 83-91 % lag;
the ICT rig's true frame 0 % lead, 93-96 % lag, except on the 9 Hz platform (26 % lead,
36 % lag: the head barely moves in the band there, and the gains are noise).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, sosfiltfilt

from facedyn.geometry import quaternion

BAND_HZ = (0.7, 5.0)  # the head's motion (walk, run, hop), below soft tissue's 5-9 Hz resonances
GAIN_HZ = 15.0  # a vertex leads or lags when it moves as tissue on a spring of this frequency or softer
LEADING = 0.1  # more than this fraction leading: the frame is not the skull's
MOST_VERTICES = 512  # left-out vertices the check looks at, evenly strided
MIN_SECONDS = 1.0


@dataclass(frozen=True)
class InertiaCheck:
    """Fractions of the checked vertices that lead and lag the frame; suspect: more than LEADING lead."""

    leading: float
    lagging: float
    vertices: int

    @property
    def suspect(self) -> bool:
        return self.leading > LEADING


def check_frame(world: np.ndarray, translate: np.ndarray, orient: np.ndarray, rest: np.ndarray,
                vertices: np.ndarray, fps: float) -> InertiaCheck | None:
    """How the vertices (indices, the soft tissue left out of the rigid mode) move in the solved frame.

    world (F, N, 3), dropped frames bridged (facedyn.stabilize.dropped); translate (F, 3) and orient (F, 4, wxyz) the frame
    to world; rest (N, 3). None where the take cannot tell: shorter than MIN_SECONDS, fps
    below four times the band's top, or fewer than 3 vertices.
    """
    frames = len(world)
    if frames < MIN_SECONDS * fps or fps < 4.0 * BAND_HZ[1] or len(vertices) < 3:
        return None
    used = vertices[np.linspace(0, len(vertices) - 1, min(MOST_VERTICES, len(vertices))).round().astype(int)]
    rot = quaternion.to_matrix(orient)
    rest = np.asarray(rest, dtype=np.float64)[used]
    carried = np.einsum("fij,nj->fni", rot, rest) + translate[:, None]  # where the frame carries each rest point
    acceleration = np.gradient(np.gradient(carried, axis=0), axis=0) * (fps * fps)
    acceleration = np.einsum("fji,fnj->fni", rot, acceleration)  # in the frame
    displacement = np.einsum("fji,fnj->fni", rot, world[:, used] - translate[:, None]) - rest
    band = butter(2, [BAND_HZ[0] / (0.5 * fps), BAND_HZ[1] / (0.5 * fps)], btype="band", output="sos")
    displacement, acceleration = sosfiltfilt(band, displacement, axis=0), sosfiltfilt(band, acceleration, axis=0)
    power = np.sum(acceleration * acceleration, axis=(0, 2))
    gain = np.sum(displacement * acceleration, axis=(0, 2)) / np.maximum(power, 1e-12)
    threshold = (2.0 * np.pi * GAIN_HZ) ** -2
    return InertiaCheck(float(np.mean(gain > threshold)), float(np.mean(gain < -threshold)), len(used))
