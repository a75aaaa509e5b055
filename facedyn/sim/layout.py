"""Smooth random fields over a face: the spatial layouts of randomized tissue.

Real tissue is not uniform: stiffness, density, damping and depth change over a few
centimetres (fat pads, muscle, thin skin over bone). Both physics of facedyn.sim vary their
material over the face by exp(variation * field), with a field from here.
"""
from __future__ import annotations

import numpy as np


def smooth_layout(points: np.ndarray, seed: int, salt: int, waves: int = 8) -> np.ndarray:
    """(N,) a smooth random field of unit RMS over `points` (cm): a sum of plane waves with
    wavelengths 6-16 cm in random directions, so neighbouring tissue is alike and the face
    varies over a few centimetres. Deterministic in (seed, salt); `salt` tells apart the
    fields of one actor (stiffness, density, ...)."""
    rng = np.random.default_rng([int(seed), int(salt)])
    direction = rng.normal(size=(waves, 3))
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    wavenumber = 2 * np.pi / rng.uniform(6.0, 16.0, waves)
    phase = rng.uniform(0.0, 2 * np.pi, waves)
    field = np.sin(np.asarray(points, dtype=np.float64) @ (direction * wavenumber[:, None]).T + phase).sum(axis=1)
    return field / np.sqrt(waves / 2.0)


# salts of the fields, one per quantity, shared by both physics
STIFFNESS, DENSITY, DAMPING, DEPTH = 1, 2, 3, 4
