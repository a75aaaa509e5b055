"""Which vertices move with the skull: per-vertex rigidity discovered from the data.

Mode pursuit on every vertex of a plain capture finds a mode, but not necessarily the
skull's: speech moves the jaw and lips most of the time, and a compromise between them and
the forehead drifts slowly with the expression (0.2-0.4 deg over seconds). The rigid mode
is the set of vertices that stay put in skull space, so it can be measured: align the
frames robustly, take each vertex's rest (its mode), and look at how far it strays from it
over the take. A vertex on the bone strays by the tracking noise only; a vertex on soft
tissue by its expressions and jiggle on top. Weights follow from that spread relative to
the noise floor (the spread of the stillest vertices), the frames are realigned on the
vertices so weighted, and the loop repeats a few rounds, each on a cleaner skull frame.

Robust to what trackers do: the spread is an upper quantile over frames (a pop moves a
vertex in one frame, which a 90 % quantile never sees), the alignment is robust
(Geman-McClure reweighting), and noise that is correlated in time or over the surface
raises the floor for every vertex alike, which the relative weights absorb.

An actor's takes share one skull: with a `prior` (the model found on the actor's other
takes) the rest is the prior's, never re-estimated, so the take is solved in the actor's
skull frame, and a vertex is rigid only where it is rigid in this take (measured against
the prior's rest) and was in the others.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facedyn.geometry import quaternion, rigid
from facedyn.stabilize import inertia
from facedyn.stabilize import rest as rest_estimate
from facedyn.stabilize.inertia import InertiaCheck

# evenly spaced frames the statistics are taken over: a 90 % quantile and a mode need no more (with 480, twice
# the cost, the 651-frame dialog and synthetic takes solved to the same errors)
SAMPLE_FRAMES = 240
ROUNDS = 3
SPREAD_QUANTILE = 90.0  # per-vertex distance to rest not exceeded in this % of frames
# the noise floor: the spread this % of vertices stay below. Not the very stillest few:
# aligned on a small patch, that patch looks stiller than the bone and the rounds lock
# onto it (a held smile while running: 5 % found 589 vertices, 0.042 cm error; 25 %, the
# bone, 0.002 cm). Faces have a quarter or more of their tracked vertices on the bone.
FLOOR_QUANTILE = 20.0
# spread / floor at or below which a vertex is fully rigid, and at or above which it
# carries no weight. Tight: bone-attached vertices of a simulated dialog spread within
# 0.99-1.08 x the floor, skin beside them that moves 0.02 cm already 1.12-1.36 x, and a
# weighted fit is biased by what its weighted vertices move, not helped by more of them.
FULL_WEIGHT = 1.1
ZERO_WEIGHT = 1.3
ICP_ITERATIONS = 5
MIN_RIGID = 3
WINDOW_SECONDS = 20.0  # consecutive seconds the inertia check of a discovered mode looks at
FIT_VERTICES = 1024  # of the weighted vertices, evenly strided, that fit each frame (the rounds, the check)


@dataclass
class RigidModel:
    """What the stabilizer found rigid: the weights and rest to solve with, and why.

    weights: (N,) in [0, 1], 1 on vertices that move with the skull; rest: (N, 3) where
    every vertex sits in skull space (its mode); spread: (N,) cm, the 90 % quantile of a
    vertex's distance to its rest over the take(s); noise_cm: the spread of the stillest
    vertices (the tracking noise floor); takes: how many takes it summarizes.
    """

    weights: np.ndarray
    rest: np.ndarray
    spread: np.ndarray
    noise_cm: float
    takes: int = 1

    def __post_init__(self) -> None:
        self.weights = np.asarray(self.weights, dtype=np.float64)
        self.rest = np.asarray(self.rest, dtype=np.float64)
        self.spread = np.asarray(self.spread, dtype=np.float64)
        n = len(self.weights)
        if self.weights.shape != (n,) or self.rest.shape != (n, 3) or self.spread.shape != (n,):
            raise ValueError(
                f"rigid model needs weights (N,), rest (N, 3) and spread (N,), got {self.weights.shape}, "
                f"{self.rest.shape} and {self.spread.shape}"
            )
        if not (np.all(np.isfinite(self.weights)) and np.all((self.weights >= 0) & (self.weights <= 1))):
            raise ValueError("rigid model weights must lie in [0, 1]")
        if np.count_nonzero(self.weights) < MIN_RIGID:
            raise ValueError(f"rigid model needs at least {MIN_RIGID} vertices with a positive weight")
        if not np.all(np.isfinite(self.rest)):
            raise ValueError("rigid model rest holds non-finite values")

    @classmethod
    def known(cls, rest: np.ndarray, weights: np.ndarray | None = None) -> "RigidModel":
        """A prior from what an actor already knows: its neutral (the skull frame) and its
        rigid weights (every vertex where it has none), with no spread measured yet."""
        rest = np.asarray(rest, dtype=np.float64)
        weights = np.ones(len(rest)) if weights is None else weights
        return cls(weights, rest, np.zeros(len(rest)), 0.0)

    def merge(self, other: "RigidModel") -> "RigidModel":
        """This model and one found on another take of the actor in the same skull frame
        (solved with this one as its prior): rigid where both are, the rest averaged over
        the takes (each weighted by how many it summarizes)."""
        if other.weights.shape != self.weights.shape:
            raise ValueError(f"cannot merge rigid models of {len(self.weights)} and {len(other.weights)} vertices")
        total = self.takes + other.takes
        rest = (self.takes * self.rest + other.takes * other.rest) / total
        return RigidModel(
            np.minimum(self.weights, other.weights), rest, np.maximum(self.spread, other.spread),
            max(self.noise_cm, other.noise_cm), total,
        )


def estimate_rigidity(
    world: np.ndarray,
    prior: RigidModel | None = None,
    *,
    seed: np.ndarray | None = None,
    width: float = 0.05,
    rounds: int = ROUNDS,
    sample_frames: int = SAMPLE_FRAMES,
) -> RigidModel:
    """Discover the rigid mode of a tracked take: world (F, N, 3) in cm, dropped frames
    already bridged (facedyn.stabilize.dropped).

    Each round aligns the sampled frames to the current rest on the current weights
    (robust ICP), re-estimates the rest (per-vertex mode at ``width`` cm; kept fixed with
    a prior) and the weights from each vertex's spread. The first round aligns to the
    first frame on every vertex (on the ``seed`` vertices, (N,) bool, where given), or to
    the prior. A prior's fully rigid vertices, or the seed, are where the noise floor is
    measured (noise_floor).
    """
    world = np.asarray(world)
    n = world.shape[1]
    if prior is not None and prior.weights.shape != (n,):
        raise ValueError(f"the prior rigid model has {len(prior.weights)} vertices, the take {n}")
    if rounds < 1:
        raise ValueError(f"rigidity rounds must be >= 1, got {rounds}")
    sample = world[rest_estimate.sample_frames(len(world), sample_frames)].astype(np.float64)
    if seed is not None and (np.shape(seed) != (n,) or np.count_nonzero(seed) < MIN_RIGID):
        raise ValueError(f"a rigidity seed must be (N,) = ({n},) bool with at least {MIN_RIGID} vertices set")
    if prior is None:
        rest, weights = sample[0], np.ones(n) if seed is None else np.asarray(seed, dtype=np.float64)
        candidates = seed
    else:
        rest, weights = prior.rest, prior.weights
        candidates = prior.weights >= 1.0
    for round_ in range(rounds):
        # the frames' fit needs no more than FIT_VERTICES of the weighted vertices; every vertex's spread is then measured
        fit = _fit_vertices(weights)
        rot, trans, _ = rigid.robust_icp(sample[:, fit], rest[fit], weights[fit], iterations=ICP_ITERATIONS)
        aligned = rigid.apply(rot, trans, sample)
        if prior is None:  # the median while the frame settles, the mode at the end
            last = round_ == rounds - 1
            rest = rest_estimate.estimate_rest(aligned, width) if last else rest_estimate.median_rest(aligned)
        spread = np.percentile(np.linalg.norm(aligned - rest, axis=-1), SPREAD_QUANTILE, axis=0)
        floor = noise_floor(spread, candidates)
        weights = _rigidity_weights(spread / floor)
        if prior is not None:
            weights = np.minimum(weights, prior.weights)
        if np.count_nonzero(weights) < MIN_RIGID:  # nothing stands out: every vertex counts
            weights = np.ones(n)
    return RigidModel(weights, rest, spread, floor)


def _fit_vertices(weights: np.ndarray) -> np.ndarray:
    """At most FIT_VERTICES of the vertices of positive weight, evenly strided: enough for a rigid fit of a frame."""
    fitted = np.flatnonzero(weights > 0)
    return fitted[rest_estimate.sample_frames(len(fitted), FIT_VERTICES)]  # evenly spaced indices


def noise_floor(spread: np.ndarray, candidates: np.ndarray | None = None) -> float:
    """The tracking noise floor (cm): the spread FLOOR_QUANTILE % of the candidate vertices stay below.

    Candidates ((N,) bool) are every vertex, or the vertices known to hold the bone: a
    prior's fully rigid ones (an actor knows where its bone is) or a seed. On a rig whose
    bone is a small part of the mesh (the ICT rig: 8 %) a quantile over every vertex lands
    on soft tissue (0.53 cm on a run) and would keep the prior's falloff, skin that slides
    against the skull, at full weight.
    """
    chosen = spread if candidates is None else spread[candidates]
    if len(chosen) < MIN_RIGID:
        chosen = spread
    return max(float(np.percentile(chosen, FLOOR_QUANTILE)), 1e-6)


def _rigidity_weights(relative_spread: np.ndarray) -> np.ndarray:
    """1 up to FULL_WEIGHT x the noise floor, easing (smoothstep) to 0 at ZERO_WEIGHT x."""
    t = np.clip((np.asarray(relative_spread) - FULL_WEIGHT) / (ZERO_WEIGHT - FULL_WEIGHT), 0.0, 1.0)
    return 1.0 - t * t * (3.0 - 2.0 * t)


@dataclass
class Discovery:
    """A discovered rigid mode, its inertia check, and the fit that check made: each checked frame (the take's
    middle WINDOW_SECONDS) aligned to the mode's rest on its weights by robust ICP (ICP_ITERATIONS, at most
    FIT_VERTICES vertices), which is mode pursuit's initial alignment of those frames, so stabilize reuses it."""

    model: RigidModel
    check: InertiaCheck | None
    frames: slice  # the take's frames the fit covers
    rot: np.ndarray  # (W, 3, 3) world -> skull
    trans: np.ndarray  # (W, 3)


def discover(world: np.ndarray, fps: float) -> Discovery:
    """discover_rigid_mode on a whole take of consecutive frames, with the fit of its middle frames."""
    frames = middle_window(len(world), fps)
    model, (check, _, rot, trans) = _discover(world, world[frames], fps)
    return Discovery(model, check, frames, rot, trans)


def discover_rigid_mode(world: np.ndarray, fps: float, window: np.ndarray | None = None) -> tuple[RigidModel, InertiaCheck | None]:
    """The rigid mode of a plain capture, and its inertia check: the skull's, not a sliding block's, where the data tell.

    world (F, N, 3): the take or an even sample of its frames (estimate_rigidity);
    window: consecutive frames of the take at ``fps`` (default: world, which must then be
    consecutive; only its middle WINDOW_SECONDS are used), where the check measures how
    the rest of the face moves in the mode's frame (facedyn.stabilize.inertia).

    When the rest of the face feeds energy into the mode's motion (a sliding block's
    frame), discovery starts again from the vertices that lead it most
    (inertia.skull_seed), and the mode so found replaces the first if the rest of the face
    is passive in its frame, as in a skull's (not suspect, and fewer vertices feed).
    On the ICT rig as simulated this finds the bone under the forehead block on walking,
    running, hopping and 9 Hz platform takes (755-840 vertices found rigid, 98-100 % of them bone);
    where it cannot, the check stays suspect and stabilize warns.
    """
    window = world if window is None else window
    model, (check, *_) = _discover(world, window[middle_window(len(window), fps)], fps)
    return model, check


def _discover(world: np.ndarray, window: np.ndarray, fps: float):
    """The mode (re-seeded where the first one's frame is suspect) and its check of `window` (_inertia's answer)."""
    model = estimate_rigidity(world)
    checked = _inertia(model, window, fps)
    check, frame = checked[0], checked[1]
    if check is None or not check.suspect:
        return model, checked
    seed = inertia.skull_seed(window, *frame, model.rest, fps)
    if seed is None or np.count_nonzero(seed) < MIN_RIGID:
        return model, checked
    reseeded = estimate_rigidity(world, seed=seed)
    again = _inertia(reseeded, window, fps)
    if again[0] is None or again[0].suspect or again[0].feeding >= check.feeding:
        return model, checked
    return reseeded, again


def middle_window(frames: int, fps: float) -> slice:
    """A take's middle WINDOW_SECONDS, where a discovered mode's inertia is checked: bounded cost and memory on long takes."""
    keep = max(1, int(round(WINDOW_SECONDS * fps)))
    start = max(0, (frames - keep) // 2)
    return slice(start, min(frames, start + keep))


def _inertia(model: RigidModel, window: np.ndarray, fps: float):
    """The inertia check of the frame a robust fit on the model's weights gives each window frame, that frame
    (skull to world: translate, orient), and the fit (world to skull: rot, trans)."""
    fitted = _fit_vertices(model.weights)
    rot, trans, _ = rigid.robust_icp(window[:, fitted].astype(np.float64), model.rest[fitted], model.weights[fitted],
                                     iterations=ICP_ITERATIONS)
    to_world = np.transpose(rot, (0, 2, 1))  # the fit maps world to skull: skull = R world + t
    frame = (-np.einsum("fij,fj->fi", to_world, trans), quaternion.from_matrix(to_world))
    return inertia.check_frame(window, *frame, model.rest, np.flatnonzero(model.weights == 0), fps), frame, rot, trans

