"""Tissue that stiffens as it moves, to first order, for an actor's linear response.

Soft tissue stiffens with strain (facedyn.sim.volumetric's energy carries a term (mu k / 4)
E^2), so a large motion rings less, and faster, than a linear response fitted on smaller
ones predicts: prototype actor 1804's hop simulated again with the stiffening off moves
1.33x more. One stiffening oscillator x'' + c x' + w^2 (x + beta x^3) = -a answers, to first
order in beta, x = x_lin - beta w^2 h * x_lin^3, h its answer to a force impulse. A linear
response already holds each sample's answer to a uniform acceleration impulse, K
(facedyn.dynamics.expression_inertia.translation_kernel, the same h up to sign and mass),
so the correction is

    d(t) = d_lin(t) + beta * (K * g(d_lin))(t),    g(v) = |v|^2 v per sample,

one number beta (cm^-2, positive for tissue that stiffens) shared by the face and fitted on
the session with the response (`fit_hardening`): the two alternate, each fitted to what the
other leaves, a fixed number of rounds. More rounds go on raising beta and taking the hop's
error down while the walk's and the platform's rise (prototype actors 1801 / 1802 / 1804,
true skull, truth targets; hop 40 / 28 / 60 % -> 35 / 28 / 55 % after four rounds, 34 / 28 /
53 % after ten, walking 54 / 35 / 76 % -> 50 / 34 / 72 % after four, 51 / 34 / 74 % after
ten), so four. A global time compression of the response (a stiffer tissue's faster ring)
reached 60 % -> 55 % on 1804's hop at its best, an output saturation by amplitude 55 %.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from facedyn.dynamics.expression_inertia import convolve

ROUNDS = 4  # alternations of the linear fit and beta


def hardening_load(kernel: np.ndarray, dynamics: np.ndarray, future: int) -> np.ndarray:
    """(F, S, 3) float64: K * g(d), what `beta` scales: the response's answer to each sample's
    cubed displacement. dynamics: (F, S, 3) the linear response's skull-driven offsets."""
    d = np.asarray(dynamics, dtype=np.float64)
    return convolve(kernel, d * np.sum(d * d, axis=-1, keepdims=True), future)


def stiffen(kernel: np.ndarray, dynamics: np.ndarray, future: int, beta: float) -> np.ndarray:
    """(F, S, 3) float64: the linear response's offsets with the stiffening added.

    First order holds while the correction is small next to the linear answer; a motion far
    beyond the session's would make a cubic grow past it and turn the answer around, so in a
    frame where the correction's norm over the face exceeds the linear answer's it is scaled
    down to it (the benchmark's hop, the largest motion it has, reaches half, actor 1804)."""
    d = np.asarray(dynamics, dtype=np.float64)
    correction = beta * hardening_load(kernel, d, future)
    size = np.linalg.norm(correction.reshape(len(d), -1), axis=1)
    bound = np.linalg.norm(d.reshape(len(d), -1), axis=1)
    scale = np.where(size > bound, bound / np.maximum(size, 1e-30), 1.0)
    return d + correction * scale[:, None, None]


def fit_beta(residuals: list, loads: list) -> float:
    """The least-squares beta of residual = beta * load over a session's takes (each (rows, 3S),
    centred per take like the fit's targets), never negative: tissue that seems to soften is
    answered linearly (a negative cubic grows without bound on a larger motion); 0 where the
    loads vanish."""
    num = sum(float(np.vdot(r, c)) for r, c in zip(residuals, loads))
    den = sum(float(np.vdot(c, c)) for c in loads)
    return max(num / den, 0.0) if den > 0 else 0.0


def fit_hardening(solve: Callable, loads_of: Callable, predictions_of: Callable, targets: list, rounds: int | None = None):
    """(fit, beta): the response and its stiffening fitted together by alternation.

    solve(targets) -> fit: the linear response fitted to those per-take targets;
    loads_of(fit) -> [(rows, 3S)]: each take's `hardening_load` of that fit's prediction,
    centred like the targets; predictions_of(fit) -> [(rows, 3S)]: its linear prediction;
    rounds: ROUNDS unless given (0: the linear fit alone).
    """
    fit = solve(targets)
    beta = 0.0
    for _ in range(ROUNDS if rounds is None else rounds):
        loads = loads_of(fit)
        beta = fit_beta([x - p for x, p in zip(targets, predictions_of(fit))], loads)
        fit = solve([x - beta * c for x, c in zip(targets, loads)])
    return fit, beta
