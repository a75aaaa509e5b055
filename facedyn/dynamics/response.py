"""An actor's linear response to skull motion, fitted on its calibration session without truth.

H trained on a family of simulated tissues predicts the family's average answer to the skull,
and going on training its network on an actor's session (`calibrate_synthesis`) moves
hundreds of thousands of weights on a few thousand frames, through targets that F makes.
A linear response has a few thousand numbers, fitted by least squares with a ridge on the
session's own captures, without F and without truth:
each calibration take holds one expression, so its skin in skull space is

    x(t) = m + G r(t) + W b(t) + noise,

m the held shape, r(t) the nine entries of the skull's rotation (gravity's direction seen
from the skull is a fixed combination of them, and the static sag follows it: the
quasistatic shape of a head that turns), b(t) the model's skull features (landmark
accelerations over t-30..t+10), W the response. m belongs to each take and is projected
out of it (the same fit as an unpenalized intercept per take); G and W are shared and
fitted together, G unpenalized. G is shared because a platform rocks the head by a tenth
of a degree at its own frequency: a sag fitted to that take alone would take up the
take's whole response, while across the session the sag is set by the gaits' slow turns.
The first `settle_s` of every take are left out: the expression settles there and its own
inertia rings. How hard W is penalized is the session's to say: each of RIDGES is fitted
without each take in turn and the one that leaves the least of the left-out takes' motion
is kept (`cross_validated_left`; prototype actors 1801 / 1802 / 1804 took 0.03, 0.03 and
1.0 where every fit before had 0.1). Leaving a take out downdates the normal equations
(the session's sums less the take's, `_Sums`) instead of refitting on the others.

W is not free: it is fitted in the modal form of a linear tissue, TEMPORAL_KERNELS time
courses over the skull window shared by every landmark and axis, each with its own map
onto the samples (`_modal_fit`). A session shakes the head up and down far more than side
to side; a free weight per lag left the sideways answer to a few takes, and the form fits
it from the time course the whole session shows. On the prototype actors (true skull,
tracker-noisy sessions, the ridges above) it took the hop's synthesis from 31 / 41 / 74%
of the true dynamics' RMS to 24 / 37 / 66% and walking removal from 53 / 39 / 55% to 50 /
37 / 51% (2 kernels: 39% on 1801's hop; 6: 26 / 69% on 1801 / 1804; 8: 25 / 38% on
1801 / 1802). Those figures, the kernel count and the stiffening's rounds below were
measured while the fit's kernel step carried no ridge, which on a skull as clean as a true
one could collapse the fit (`_modal_fit`); on the test set's validation actors (solved
skull) the fit with the ridge answers as before.

Tissue stiffens as it moves: a hop rings less than a linear fit on the session's smaller
motions says. The fit therefore carries one more number, the stiffening beta of a first-order
correction d + beta K * |d|^2 d (facedyn.dynamics.hardening; K the response's own answer to an
acceleration impulse), fitted with the response by alternation on the whole session (a
take left out keeps the session's beta) and recorded as `hardening`;
synthesis and removal both apply it. Files fitted before it carry no `hardening` and answer
linearly, as they did.

The result is a model of its own kind, "response" (file suffix .response), set up like H
(the template's samples, landmarks, stretch setup and skull input), whose network is one
linear layer that reads no stretch: what the response
cannot say is how an expression changes the tissue's answer. With zero skull acceleration
it predicts zero dynamics. Since it reads the skull alone, it also removes: the capture
minus the dynamics it predicts from the solved skull (`remove_with_response`, `usdfacedyn
remove --model` of a linear response), plus its answer to the capture's own skin
acceleration below the tissue's band, the load of a moving expression
(facedyn.dynamics.expression_inertia; recorded as `expression_inertia_hz`, the cut-off).
Synthesis answers the same load on the quasistatic skin it is given (`synthesized_dynamics`).
`benchmarks/bench_cross_sim.py` has what it gives on tissue of another simulator family; the
README quotes it.
"""
from __future__ import annotations

import copy
import dataclasses
from typing import Callable, Iterable, Iterator

import numpy as np

from facedyn.blas import single_threaded_blas
from facedyn.dynamics.diagnostics import motion_left_beyond_sag
from facedyn.dynamics.expression_inertia import LOWPASS_HZ, expression_inertia, translation_kernel
from facedyn.dynamics.hardening import fit_hardening, hardening_load, stiffen
from facedyn.dynamics.features import check_fps
from facedyn.dynamics.modelfile import DynamicsModel
from facedyn.dynamics.netspec import NetworkSpec
from facedyn.dynamics.network_weights import NetworkWeights
from facedyn.dynamics.skull import check_points, check_transforms, skull_space
from facedyn.dynamics.skull_motion import SkullMotionInput
from facedyn.dynamics.spikes import replace_spikes
from facedyn.dynamics.training_sequence import TrainingSequence
from facedyn.errors import FacedynError
from facedyn.geometry import quaternion

SETTLE_S = 0.4  # the simulated sessions ease their expression in over 0.3 s
RIDGES = (0.01, 0.03, 0.1, 0.3, 1.0)  # penalties per frame on the standardized skull features, one chosen per session
RIDGE = 0.1  # the penalty of a session of one take, which has no other take to choose by
MIN_ROWS = 20  # settled frames a take needs to count
TEMPORAL_KERNELS = 4  # kernels over the skull window the response's channels share (`_modal_fit`)
ALTERNATIONS = 15  # rounds of kernels-then-maps least squares


def fit_linear_response(model: DynamicsModel, takes: Iterable, *, settle_s: float = SETTLE_S, ridge: float | None = None,
                        on_candidate: Callable[[], None] | None = None) -> DynamicsModel:
    """A response model with ``model``'s setup (a synthesis model or a response) whose network
    is the takes' linear response.

    takes: TrainingSequences (or dicts) of one actor, each holding one expression under
    skull motion (platforms, walks, jumps...), all at the model's frame rate; ridge: the
    penalty (None: the one of RIDGES the session's cross-validation prefers; RIDGE for one
    take); on_candidate: called after each penalty tried (progress).
    """
    if model.kind not in ("synthesis", "response"):
        raise ValueError(f"fit_linear_response needs a synthesis model (or a response) as its template, got a {model.kind!r} model")
    if ridge is not None and not ridge > 0:
        raise ValueError(f"ridge must be positive, got {ridge}")
    session, described = [], []
    for take in map(TrainingSequence.coerce, takes):
        rows = _take_rows(take, model, settle_s)
        session.append(rows)
        described.append({"name": take.name, "frames": int(len(take.points)), "rows": int(len(rows.targets))})
    if not described:
        raise ValueError("a linear response needs at least one take")
    sums = _Sums.total(session)
    if not np.any(sums.squares > 0):
        raise FacedynError(f"the takes {[d['name'] for d in described]} hold no skull motion after their first {settle_s:g} s: a "
                         "linear response is fitted on held expressions under motion (platforms, walks, jumps)")
    candidates = RIDGES if ridge is None and len(session) > 1 else (RIDGE if ridge is None else float(ridge),)
    left_by_ridge, fits = {}, {}
    for candidate in candidates:
        session_fit = _session_fit(session, sums, candidate, model)
        fits[candidate] = session_fit[:2]  # the fit and its beta: a session's targets are large
        left_by_ridge[candidate] = _left(session, sums, candidate, session_fit, model) if len(session) > 1 else None
        if on_candidate is not None and len(candidates) > 1:
            on_candidate()
    ridge = min(left_by_ridge, key=lambda r: left_by_ridge[r]) if len(candidates) > 1 else candidates[0]
    left = left_by_ridge[ridge]
    (weights, scale), beta = fits[ridge][:2]
    network = _linear_network(model.network.spec, weights, scale)
    record = {"response": "linear", "takes": described, "rows": int(sum(len(rows.targets) for rows in session)), "settle_s": float(settle_s),
              "ridge": ridge, "session_cross_validated_left": None if left is None else round(left, 4),
              "ridge_candidates": {f"{r:g}": None if v is None else round(v, 4) for r, v in left_by_ridge.items()},
              "expression_inertia_hz": LOWPASS_HZ, "hardening": beta, "temporal_kernels": TEMPORAL_KERNELS}
    info = {**copy.deepcopy(model.info), "calibration": record, "validation": None}
    return DynamicsModel(kind="response", network=network, face=model.face, fps=model.fps, windows=dict(model.windows), info=info,
                         arrays=dict(model.arrays), skull_motion=model.skull_input)


def response_template(face, fps: float, info: dict | None = None) -> DynamicsModel:
    """The setup a response is fitted with where the actor has no network H to take it from
    (`usdfacedyn calibrate`): the face's samples and landmarks (an F's), the landmarks'
    accelerations over t-30..t+10, no stretch (a response reads none)."""
    motion = SkullMotionInput()
    spec = NetworkSpec(len(face.landmarks) * motion.width * 3, (), 3 * len(face.samples))
    empty = _linear_network(spec, np.zeros((spec.inputs, spec.outputs)), np.ones(spec.inputs))
    return DynamicsModel(kind="response", network=empty, face=face, fps=float(fps), windows={}, info=dict(info or {}),
                         skull_motion=motion)


def settled_frames(frame_count: int, fps: float, settle_s: float, model: DynamicsModel) -> slice:
    """The frames of a take a response is fitted on: after the expression settles, before the
    skull windows read past the take's end."""
    return slice(int(round(settle_s * fps)), frame_count - model.skull_input.future - 1)


def cross_validated_left(session: list, ridge: float, model: DynamicsModel) -> float:
    """How much of the session's motion a response fitted without each take leaves in it.

    Each take's motion beyond its held shape and the session's rotation-following sag,
    less what the response fitted on the other takes predicts: the fraction left
    (facedyn.dynamics.diagnostics.motion_left_beyond_sag; 0: the actor's tissue answers
    every motion of the session as one linear system; near 1: it does not, e.g. tissue
    that stiffens with strain or with the expression). The same fraction of a removal
    model's output (`usdfacedyn evaluate --session`) compares the two on one actor.
    """
    sums = _Sums.total(session)
    return _left(session, sums, ridge, _session_fit(session, sums, ridge, model), model)


def _left(session: list, sums: "_Sums", ridge: float, session_fit: tuple, model: DynamicsModel) -> float:
    """`cross_validated_left` given the session's sums and fit (`_session_fit`)."""
    left = [rows.targets - _predict(rows, fit, model) for rows, fit in zip(session, _fits_without_each(session, sums, ridge, session_fit, model))]
    return motion_left_beyond_sag(left, [rows.targets for rows in session], [rows.rotations for rows in session])


def _fits_without_each(session: list, sums: "_Sums", ridge: float, session_fit: tuple, model: DynamicsModel):
    """For each take in turn, the response fitted on all the other takes: (weights, scale, beta).

    The normal equations are downdated: the session's sums less the take's own
    (`_Sums`), solved in the modal form as the whole session's are. The stiffening is one
    number of the face, fitted with the whole session (`_session_fit`): a left-out fit
    keeps its beta and the targets it leaves (each take's less beta times its load), so
    leaving a take out costs one solve, not a refit with its alternation over every other
    take (on a 70-take session, 70 refits per candidate penalty took more than an hour).
    """
    _, beta, targets, moments = session_fit
    for rows, target in zip(session, targets):
        own = _moments([rows], [target])
        solve = _solver(sums - _Sums.of(rows), ridge, len(model.face.landmarks), model.skull_input.width)
        yield (*solve(moments[0] - own[0], moments[1] - own[1]), beta)


@dataclasses.dataclass(frozen=True)
class _TakeRows:
    """One calibration take as the fit reads it: the skull features of every frame, the
    settled frames fitted on, and their rotation entries and sample coordinates, each less its
    mean over those frames (the held shape's intercept)."""

    all_features: np.ndarray  # (frames, skull features) float64
    keep: slice
    rotations: np.ndarray  # (rows, 9)
    targets: np.ndarray  # (rows, 3S)

    @property
    def features(self) -> np.ndarray:
        b = self.all_features[self.keep]
        return b - b.mean(axis=0)


@dataclasses.dataclass(frozen=True)
class _Sums:
    """The normal equations' sums over takes' settled rows that do not depend on the targets:
    the skull features b (each take's less its mean) squared and crossed, with the rotation
    entries r (the sag). A session's are the sum of its takes', so a take is left out by
    subtracting its own."""

    rows: int
    squares: np.ndarray  # (features,) sum of b^2: the features' scale
    bb: np.ndarray  # (features, features)
    rb: np.ndarray  # (9, features)
    rr: np.ndarray  # (9, 9)

    @classmethod
    def of(cls, rows: _TakeRows) -> "_Sums":
        b, r = rows.features, rows.rotations
        return cls(len(b), np.sum(b * b, axis=0), b.T @ b, r.T @ b, r.T @ r)

    @classmethod
    def total(cls, session: list) -> "_Sums":
        total = cls.of(session[0])
        for rows in session[1:]:  # one take's matrices made at a time
            total = total + cls.of(rows)
        return total

    def __add__(self, other: "_Sums") -> "_Sums":
        return _Sums(*(getattr(self, f.name) + getattr(other, f.name) for f in dataclasses.fields(self)))

    def __sub__(self, other: "_Sums") -> "_Sums":
        return _Sums(*(getattr(self, f.name) - getattr(other, f.name) for f in dataclasses.fields(self)))


def _moments(session: list, targets: list) -> tuple[np.ndarray, np.ndarray]:
    """(b't (features, 3S), r't (9, 3S)): the targets' sums over the takes' settled rows."""
    bt = sum(rows.features.T @ t for rows, t in zip(session, targets))
    rt = sum(rows.rotations.T @ t for rows, t in zip(session, targets))
    return bt, rt


def _session_fit(session: list, sums: _Sums, ridge: float, model: DynamicsModel) -> tuple:
    """((weights, scale), hardening beta, targets, their moments): the response and the tissue's stiffening
    fitted together on the session by alternation (facedyn.dynamics.hardening): each fitted to
    what the other leaves, its rounds; targets: each take's that the last solve fitted (its
    centred skin less beta times its load under the fit before)."""
    solve = _solver(sums, ridge, len(model.face.landmarks), model.skull_input.width)
    solved = []

    def solve_for(targets: list) -> tuple:
        moments = _moments(session, targets)
        solved[:] = [(targets, moments)]  # the last only: a session's targets are large
        return solve(*moments)

    fit, beta = fit_hardening(solve_for, lambda fit: _centred_loads(session, fit, model),
                              lambda fit: [(rows.features / fit[1]) @ fit[0] for rows in session], [rows.targets for rows in session])
    return (fit, beta, *solved[-1])


def _centred_loads(session: list, fit: tuple, model: DynamicsModel) -> list:
    """[(rows, 3S)]: each take's hardening load under a fit (weights, scale), on its settled
    frames less its mean there, like the targets."""
    weights, scale = fit[:2]
    motion = model.skull_input
    kernel = translation_kernel(weights / scale[:, None], len(model.face.landmarks), motion.past, motion.future)
    loads = []
    for rows in session:
        dynamics = ((rows.all_features / scale) @ weights).reshape(len(rows.all_features), -1, 3)
        load = hardening_load(kernel, dynamics, motion.future)[rows.keep].reshape(len(rows.targets), -1)
        loads.append(load - load.mean(axis=0))
    return loads


def _predict(rows: _TakeRows, fit: tuple, model: DynamicsModel) -> np.ndarray:
    """(rows, 3S): what a fit (weights, scale, beta) predicts of a take's centred targets."""
    weights, scale, beta = fit
    return (rows.features / scale) @ weights + beta * _centred_loads([rows], fit, model)[0]


def _solver(sums: _Sums, ridge: float, landmarks: int, width: int) -> Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """(b't, r't) moments -> (response weights on the scaled skull features (features, 3S), the
    features' scale) in the modal form (`_modal_fit`): ridge on the spatial maps, the shared
    sag on the rotation entries unpenalized (projected out of the normal equations, which is
    the same least squares). The Gram matrix is formed once: the stiffening's alternation
    solves again for each round's targets. Every solve here is NumPy's: SciPy's LAPACK calls
    run on its own OpenBLAS threads, which interleaved with NumPy's fight over the cores (a fit
    several times slower on 2 cores)."""
    scale = np.sqrt(sums.squares / sums.rows)
    scale = np.where(scale > 1e-12, scale, 1.0)
    sag = np.linalg.pinv(sums.rr, rcond=1e-10, hermitian=True)
    gram = (sums.bb - sums.rb.T @ sag @ sums.rb) / np.outer(scale, scale)
    penalty = ridge * sums.rows
    penalized = gram + penalty * np.eye(len(gram))

    def solve(bt: np.ndarray, rt: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        with single_threaded_blas():  # many small products: threads only spin (facedyn.blas)
            moments = (bt - sums.rb.T @ (sag @ rt)) / scale[:, None]
            full = np.linalg.solve(penalized, moments)
            return _modal_fit(gram, moments, full, penalty, landmarks, width), scale

    return solve


def _modal_fit(gram: np.ndarray, moments: np.ndarray, full: np.ndarray, penalty: float, landmarks: int, width: int) -> np.ndarray:
    """(features, 3S): the response as TEMPORAL_KERNELS kernels over the skull window shared by
    every skull channel (landmark and axis), each with its own map from channels to samples:
    W[lag, channel, sample] = sum_r h_r[lag] A_r[channel, sample].

    A linear tissue answers an acceleration through its modes, each ringing with its own
    impulse response and excited by every channel through its participation, so the form
    holds for it; it asks a session for far fewer numbers than a free weight per lag, so a
    direction the session moves the head in less (side to side) is fitted from the time
    course the whole session shows. Fitted by alternating least squares on the features'
    Gram matrix and moments, the kernels started from the leading singular vectors of the
    plain ridge fit `full`. Both steps minimize the same objective as `full`, the ridge on the
    weights |W|^2 = sum_rs (h_r . h_s)(A_r . A_s) included: each step's penalty is the other
    factor's overlaps. A kernel step without it (the maps alone penalized) is nearly singular
    where the skull's motion is exactly rigid (a clean skull track: landmark accelerations span
    few directions) and blew up into those directions, and the fit collapsed to nothing (on
    true session dynamics under the true skull it left 88 % of the session's motion where the
    plain ridge fit left 20 %). The contractions go through BLAS (einsum's optimize), five
    times faster than its loops.
    """
    channels, outputs, rank = 3 * landmarks, full.shape[1], TEMPORAL_KERNELS

    def by_lag(a: np.ndarray) -> np.ndarray:  # features (landmark, lag, axis) first -> (lag, channel, ...)
        return np.moveaxis(a.reshape(landmarks, width, 3, *a.shape[1:]), 1, 0).reshape(width, channels, *a.shape[1:])

    g = by_lag(by_lag(gram).reshape(width * channels, -1).T).reshape(width, channels, width, channels)  # symmetric
    m = by_lag(moments)
    by_lag_full = full.reshape(landmarks, width, 3 * outputs).transpose(1, 0, 2).reshape(width, -1)
    kernels = np.linalg.eigh(by_lag_full @ by_lag_full.T)[1][:, ::-1][:, :rank]  # its leading left singular vectors

    def maps_for(kernels: np.ndarray) -> np.ndarray:
        lhs = np.einsum("kcld,kr,ls->rcsd", g, kernels, kernels, optimize=True).reshape(rank * channels, rank * channels)
        rhs = np.einsum("kco,kr->rco", m, kernels, optimize=True).reshape(rank * channels, outputs)
        overlaps = kernels.T @ kernels  # (rank, rank): the kernels' share of |W|^2
        return np.linalg.solve(lhs + penalty * np.kron(overlaps, np.eye(channels)), rhs).reshape(rank, channels, outputs)

    for _ in range(ALTERNATIONS):
        maps = maps_for(kernels)
        if not np.any(maps):  # targets the motion does not move at all: nothing for the kernels to fit
            break
        overlaps = np.einsum("rco,sdo->rscd", maps, maps, optimize=True)
        lhs = np.einsum("kcld,rscd->rksl", g, overlaps, optimize=True).reshape(rank * width, rank * width)
        lhs += penalty * np.kron(np.einsum("rscc->rs", overlaps), np.eye(width))  # the maps' share of |W|^2
        lhs += 1e-9 * np.trace(lhs) / len(lhs) * np.eye(len(lhs))
        rhs = np.einsum("kco,rco->rk", m, maps, optimize=True).reshape(-1)
        kernels = np.linalg.solve(lhs, rhs).reshape(rank, width).T
        kernels = kernels / np.linalg.norm(kernels, axis=0)
    weights = np.einsum("kr,rco->kco", kernels, maps_for(kernels), optimize=True)
    return np.moveaxis(weights.reshape(width, landmarks, 3, outputs), 0, 1).reshape(-1, outputs)


def calibration_names(model: DynamicsModel) -> dict[str, int]:
    """The takes a linear response was fitted on: {name: frames}."""
    return {t["name"]: int(t["frames"]) for t in model.info["calibration"]["takes"]}


def remove_left_out(model: DynamicsModel, takes: list) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Each of the response's own calibration takes removed by the response refitted on the
    others, in order, one take at a time: (quasistatic skull-space points, offsets), float32.

    What the response does to a take it has seen flatters it; refitted without the take (the
    model's own settle and ridge, its normal equations downdated, the session's stiffening
    kept: `_fits_without_each`), it removes as it would from a new capture, so its
    figures on its session compare with a removal model's (`usdfacedyn evaluate --session
    --removal RESPONSE`). takes: TrainingSequences, exactly the model's calibration takes.
    """
    if not is_linear_response(model):
        raise ValueError("remove_left_out needs a linear response (fit_linear_response)")
    takes = [TrainingSequence.coerce(take) for take in takes]
    given = {take.name: len(take.points) for take in takes}
    if given != calibration_names(model) or len(given) != len(takes):
        raise ValueError(f"remove_left_out needs the response's calibration takes {sorted(calibration_names(model))}, "
                         f"each whole; got {sorted(given)}")
    if len(takes) < 2:
        raise ValueError("a response fitted on one take has no other take to be refitted on")
    record = model.info["calibration"]
    session = [_take_rows(take, model, record["settle_s"]) for take in takes]
    sums = _Sums.total(session)
    fits = _fits_without_each(session, sums, record["ridge"], _session_fit(session, sums, record["ridge"], model), model)
    return (_removed_by_refit(take, model, fit) for take, fit in zip(takes, fits))


def _removed_by_refit(take: TrainingSequence, model: DynamicsModel, fit: tuple) -> tuple[np.ndarray, np.ndarray]:
    """A take removed by the response with another fit's weights, scale and stiffening (remove_left_out)."""
    weights, scale, beta = fit
    record = model.info["calibration"]
    info = {**model.info, "calibration": {**record, "hardening": beta}} if "hardening" in record else model.info
    refitted = dataclasses.replace(model, network=_linear_network(model.network.spec, weights, scale), info=info)
    return remove_with_response(take.points, take.translate, take.orient, take.fps, refitted, space=take.space)


def is_linear_response(model: DynamicsModel) -> bool:
    """Whether a model is an actor's linear response (reads the skull alone): its kind says
    (files written before the kind existed load as one, facedyn.dynamics.modelfile)."""
    return model.kind == "response"


def remove_with_response(points, translate, orient, fps: float, model: DynamicsModel, *,
                         space: str = "skull") -> tuple[np.ndarray, np.ndarray]:
    """(quasistatic skull-space points, offsets), float32: the capture minus the dynamics the
    linear response predicts from the skull; arguments as facedyn.dynamics.removal.remove_dynamics."""
    if not is_linear_response(model):
        raise ValueError("remove_with_response needs a linear response (fit_linear_response); a synthesis network reads the "
                         "quasistatic shape it would make")
    pts = check_points(points)
    if pts.shape[1] != model.face.point_count:
        raise ValueError(f"the take has {pts.shape[1]} points per frame, the model's mesh {model.face.point_count}")
    model.check_compatible(fps=check_fps(fps))
    t, q = check_transforms(translate, orient, len(pts))
    b = model.skull_input.features(t, q, model.face.landmarks, fps)
    skull_points = skull_space(pts, t, q, space)
    d = _dynamics(model, b, skull_points[:, model.face.samples], fps, skin_holds_dynamics=True)
    offsets = np.empty((len(pts), pts.shape[1], 3), np.float32)
    model.propagator().apply_into(np.ascontiguousarray(d, dtype=np.float32), offsets)
    return skull_points.astype(np.float32) - offsets, offsets


def synthesized_dynamics(model: DynamicsModel, skull_features: np.ndarray, quasistatic_samples: np.ndarray,
                         fps: float) -> np.ndarray:
    """(frames, S, 3) float32: what a linear response synthesizes for a quasistatic skin under
    a skull motion: the skull-driven dynamics plus its answer to the skin's own acceleration
    below the recorded cut-off (the expression's inertia, as removal answers it), so that what
    removal takes out comes back closer when synthesized on the same skull. quasistatic_samples:
    (frames, S, 3) the skin at the model's samples in skull space, spikes replaced as removal
    reads the capture (a quasistatic layer keeps the capture's pops). Files fitted before the
    term synthesize from the skull alone, as they did."""
    return _dynamics(model, skull_features, quasistatic_samples, fps, skin_holds_dynamics=False)


def _dynamics(model: DynamicsModel, skull_features: np.ndarray, skin: np.ndarray, fps: float, *,
              skin_holds_dynamics: bool) -> np.ndarray:
    """(frames, S, 3) float32: the skull-driven dynamics plus the answer to the skin's own
    acceleration below the recorded cut-off (files fitted before the term: the skull alone).
    skin: (frames, S, 3) skull-space samples, spikes not yet replaced; skin_holds_dynamics: a
    capture (removal), whose load is the skin less the skull-driven dynamics, rather than a
    quasistatic skin (synthesis)."""
    lowpass = model.info["calibration"].get("expression_inertia_hz")
    kernel = _kernel(model) if lowpass is not None or _hardening(model) else None
    d = _skull_driven(model, skull_features, kernel)
    if lowpass is None:
        return d
    load, _ = replace_spikes(skin)
    if skin_holds_dynamics:
        load = load - d
    return d + expression_inertia(kernel, load, fps, model.skull_input.future, lowpass).astype(np.float32)


def _skull_driven(model: DynamicsModel, skull_features: np.ndarray, kernel: np.ndarray | None) -> np.ndarray:
    """(frames, S, 3) float32: the samples' offsets the response predicts from a take's skull
    features (every frame of it, in order: its stiffening reads neighbouring frames), with its
    impulse kernel given (None: the model has no stiffening). Files fitted before the
    stiffening carry no `hardening` and answer linearly, as they did."""
    d = _respond(model, skull_features).reshape(len(skull_features), -1, 3)
    beta = _hardening(model)
    return d if not beta else stiffen(kernel, d, model.skull_input.future, beta).astype(np.float32)


def _hardening(model: DynamicsModel) -> float:
    """The response's recorded stiffening beta (0 for files fitted before it); a clear error if
    the file's value is not a non-negative number."""
    beta = model.info["calibration"].get("hardening", 0.0)
    if isinstance(beta, bool) or not isinstance(beta, (int, float)) or not np.isfinite(beta) or beta < 0:
        raise ValueError(f"the linear response's calibration.hardening must be a non-negative number, got {beta!r}")
    return float(beta)


def _kernel(model: DynamicsModel) -> np.ndarray:
    """The response's answer to a uniform acceleration impulse (expression_inertia.translation_kernel)."""
    return translation_kernel(_raw_weights(model), len(model.face.landmarks), model.skull_input.past, model.skull_input.future)


def _respond(model: DynamicsModel, skull_features: np.ndarray) -> np.ndarray:
    """(rows, 3S) float32: the response's samples' offsets for rows of skull features (one
    linear layer, applied in NumPy: a GPU would buy nothing)."""
    inputs = np.zeros((len(skull_features), model.network.spec.inputs), np.float32)  # the stretch it does not read stays zero
    inputs[:, : skull_features.shape[1]] = skull_features
    return model.weights.forward(inputs)


def _raw_weights(model: DynamicsModel) -> np.ndarray:
    """(skull features, 3S) float64: the response's weights on unscaled skull features (its
    answer to each feature alone: the network is linear and zero at zero)."""
    return _respond(model, np.eye(model.skull_input.width * 3 * len(model.face.landmarks), dtype=np.float32)).astype(np.float64)


def _take_rows(take: TrainingSequence, model: DynamicsModel, settle_s: float) -> _TakeRows:
    """A calibration take as the fit reads it (`_TakeRows`)."""
    pts = check_points(take.points, f"take {take.name!r} points")
    if pts.shape[1] != model.face.point_count:
        raise ValueError(f"take {take.name!r} has {pts.shape[1]} points, the model's mesh {model.face.point_count}")
    fps = check_fps(take.fps)
    model.check_compatible(fps=fps)
    t, q = check_transforms(take.translate, take.orient, len(pts))
    keep = settled_frames(len(pts), fps, settle_s, model)
    rows = keep.stop - keep.start
    if rows < MIN_ROWS:
        raise ValueError(f"take {take.name!r} has {len(pts)} frames; a linear response needs at least {MIN_ROWS} after its first "
                         f"{settle_s:g} s (the expression settling) and before its last {model.skull_input.future + 1}")
    x, _ = replace_spikes(skull_space(pts[:, model.face.samples], t, q, take.space))
    b = model.skull_input.features(t, q, model.face.landmarks, fps).astype(np.float64)
    x = x[keep].reshape(rows, -1)
    r = quaternion.to_matrix(q[keep]).reshape(-1, 9)
    return _TakeRows(b, keep, r - r.mean(0), x - x.mean(0))


def _linear_network(template: NetworkSpec, weights: np.ndarray, scale: np.ndarray) -> NetworkWeights:
    """One linear layer over the template's inputs (skull features, then stretch, which it
    does not read) with inputs scaled but not centred: zero skull motion, zero dynamics."""
    skull_count, outputs = weights.shape
    layer = np.zeros((outputs, template.inputs), np.float32)
    layer[:, :skull_count] = weights.T
    std = np.ones(template.inputs)
    std[:skull_count] = scale
    return NetworkWeights.normalized(NetworkSpec(template.inputs, (), outputs), [(layer, np.zeros(outputs))],
                                     np.zeros(template.inputs), std, np.zeros(outputs), 1.0)
