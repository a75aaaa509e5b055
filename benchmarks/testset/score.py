"""The test set's error figure: the fraction of the true dynamics' RMS that a removal leaves.

The same figure as bench_cross_sim.py and the issue's targets: RMS over the scored vertices
(the actor's face_vertices in truth.npz) and frames of (estimated dynamics - true dynamics),
divided by the RMS of the true dynamics (facedyn.evaluation.residual_fraction): doing nothing
(estimating no dynamics) scores 100 %. Estimates are skull-space offsets in the actor's frame
(a take stabilized with `--actor` from the actor's rig.usda), as a quasistatic layer holds them.
A take stabilized without `--actor` is in its own skull frame: its estimates are turned into
the actor's by `frame_rotation` first.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from facedyn.dynamics.targets import dynamic_offsets
from facedyn.evaluation import residual_fraction


def load_truth(actor: Path, take: str) -> dict:
    path = Path(actor) / "takes" / take / "truth.npz"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such take's truth (takes are folders under {Path(actor) / 'takes'})")
    with np.load(path) as data:
        return {key: data[key] for key in data.files}


def fraction_left(estimate: np.ndarray, truth: dict) -> float:
    """RMS(estimate - true dynamics) / RMS(true dynamics) over the scored vertices."""
    dynamics = truth["dynamics"]
    if estimate.shape != dynamics.shape:
        raise ValueError(f"the estimate has shape {estimate.shape}, the truth {dynamics.shape} (frames, points, 3)")
    return residual_fraction(estimate, dynamics, dynamics, truth["face_vertices"])["fraction"]


def moving_left(estimate: np.ndarray, truth: dict) -> float:
    """RMS of (estimate - true dynamics), each less its mean over the take, / RMS of the true
    dynamics less its mean, over the scored vertices: how much of the part of the truth that
    moves an estimate leaves, the static share (which no truth-free method sees) set apart."""
    dynamics = np.asarray(truth["dynamics"], dtype=np.float64)[:, truth["face_vertices"]]
    estimate = np.asarray(estimate, dtype=np.float64)
    if estimate.shape != truth["dynamics"].shape:
        raise ValueError(f"the estimate has shape {estimate.shape}, the truth {truth['dynamics'].shape} (frames, points, 3)")
    residual = estimate[:, truth["face_vertices"]] - dynamics
    moving = dynamics - dynamics.mean(axis=0)
    return float(np.sqrt(np.sum((residual - residual.mean(axis=0)) ** 2) / np.sum(moving ** 2)))


def frame_rotation(stabilized_points: np.ndarray, truth: dict) -> np.ndarray:
    """(3, 3) A: the rotation from a take's own skull frame (stabilized without --actor) to the
    actor's, one least-squares fit (Kabsch) of every frame's stabilized points to the true
    captured skin; a vector v of the take's frame is A v in the actor's."""
    ours = np.asarray(stabilized_points, dtype=np.float64).reshape(-1, 3)
    theirs = np.asarray(truth["captured"], dtype=np.float64).reshape(-1, 3)
    ours, theirs = ours - ours.mean(axis=0), theirs - theirs.mean(axis=0)
    u, _, vt = np.linalg.svd(theirs.T @ ours)
    d = np.sign(np.linalg.det(u @ vt))
    return u @ np.diag([1.0, 1.0, d]) @ vt


def moving_average_estimate(stabilized_points: np.ndarray, truth: dict) -> np.ndarray:
    """The 21-frame moving average baseline (bench_cross_sim's): the stabilized skin minus its
    moving average, on the scored vertices (0 elsewhere)."""
    fv = truth["face_vertices"]
    estimate = np.zeros_like(truth["dynamics"], dtype=np.float64)
    estimate[:, fv] = dynamic_offsets(np.asarray(stabilized_points)[:, fv], space="skull")
    return estimate


def static_share(truth: dict) -> float:
    """RMS of the true dynamics' mean over the take / RMS of the true dynamics, over the scored
    vertices: the part of the truth that does not move (tissue that settles elsewhere while the
    head shakes). An estimate whose offsets average to zero over the take (a linear response to
    the skull's acceleration does) cannot score below it."""
    dynamics = np.asarray(truth["dynamics"], dtype=np.float64)[:, truth["face_vertices"]]
    mean = dynamics.mean(axis=0)
    return float(np.sqrt(np.sum(mean ** 2, axis=-1).mean() / np.sum(dynamics ** 2, axis=-1).mean()))


def dynamics_rms_mm(truth: dict) -> float:
    return residual_fraction(truth["dynamics"], truth["dynamics"], truth["dynamics"], truth["face_vertices"])["dynamics_rms_cm"] * 10
