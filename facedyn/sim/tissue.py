"""Ground-truth soft tissue: a damped elastic skin layer attached to a moving skull.

The captures of the papers are not public, so facedyn makes takes whose truth is known:
the expression rig gives the quasistatic (jiggle-free) skin y(t) in skull space and this
module adds the secondary dynamics u(t) that a real skull motion would cause, x = y + u.

Model (skull frame, lumped masses M = Voronoi areas; the areal density cancels because
every load is inertial):

    M u'' + C u' + K(t) u = -M [a0 + alpha x r + 2 omega x r' + omega x (omega x r)
                                - (g(t) - g(0))]

- r = y + u is a vertex's position and r' = y' + u' its velocity in the skull frame;
  a0 is the skull origin's acceleration, omega and alpha the skull's angular velocity and
  acceleration, all in skull axes (Euler, Coriolis and centrifugal loads). g(t) is world
  gravity seen from the skull, relative to the first frame's orientation, so a skull held
  still in any pose stays exactly at rest.
- By default the expression itself does not force the tissue (y'' is no load): with a
  still skull the output is y(t) exactly, for any expression sequence, so y is an exact
  truth. `expression_inertia` e > 0 adds -M e y''(t): the tissue's own inertia as the
  expression moves it (passive tissue carries all of it, e = 1; muscles that shape the
  expression from within carry part of it, so e < 1), the load a fast lip or jaw motion
  puts on the tissue around it.
- K(t) = M diag(w_i^2 s_i(t) A_i) + c^2 L: a spring to the bone whose natural frequency w_i
  rises from `soft_hz` (rigid weight 0: cheeks, lips, jowls) to `bone_hz` (weight -> 1),
  raised where the soft tissue is thinner (`depth_variation`, see TissueParams),
  and a membrane (cotangent Laplacian L of the neutral, c = coupling_cm * 2 pi soft_hz)
  that makes neighbours pull on each other, so offsets are smooth fields.
  A_i = I + (normal_ratio^2 - 1) n_i n_i^T makes the spring stiffer along the neutral's
  normal n_i (tissue is nearly incompressible: pushing the skin into it is harder than
  shearing it along the bone; normal_ratio 1 is the isotropic spring).
  s_i(t) = 1 + strain_stiffening * |strain_i(t)| stiffens tissue the expression stretches
  or compresses (mean |l / l_neutral - 1| over the vertex's edges), so one skull motion
  jiggles differently under different expressions. Weight-1 vertices are held at y(t).
- C = a M + b K_0 (Rayleigh, K_0 the neutral's stiffness) with `damping_ratio` at
  `soft_hz` and at `bone_hz`; the slowest ring-down loses 90 % in about 0.2 s.

Gravity: turning the head turns gravity in the skull frame, and the tissue sags towards it.
Held in the new pose, the skin would stay sagged: that static part is the quasistatic
shape of the pose, not secondary dynamics (nothing about it depends on how the head got
there, and features built from velocities cannot see a pose). `gravity_sag` is that
static response, K(t) s(t) = M (g(t) - g(0)), and `dynamics` = u - s is the part caused
by motion, the truth that removal and synthesis are measured against.

Integration: two-stage Gauss-Legendre (implicit, A-stable, fourth order), so one step per
120 fps frame agrees with eight to within about 1 % even at 11 Hz. The eigenvectors of its
Butcher matrix decouple the stage equations into one complex sparse system
(M + mu C + mu^2 K) w = rhs per step, factorized once and reused (one system of the
vertices for x, y and z alike when the springs are isotropic, one of all 3n coordinates
when normal_ratio > 1). The expression-dependent
part of K and the u-dependent fictitious loads enter the right-hand side at stage values
predicted from the previous step; the matrix is refactorized only when the stiffness drift
would change its diagonal by more than `refactor_tolerance` (relative), or when the
stiffness left explicit would break the explicit part's stability bound (h^2 k above
EXPLICIT_LIMIT: a Live Link curve that never quite holds still kept a correction below the
tolerance for seconds, and it grew to metres on springs stiff along the normal). A still skull
gives a zero right-hand side, hence exactly zero offsets. Those explicit parts can feed a
stiff mode that Gauss-Legendre does not damp; a take whose offsets leave what tissue does
(MAX_DEFLECTION_CM, or the face's size) is stopped at that frame and integrated again at
twice the steps per frame
(`substep_ladder`), so a divergence costs time, not the take.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.interpolate import CubicSpline

from facedyn.blas import single_threaded_blas
from facedyn.errors import FacedynError
from facedyn.geometry import mesh, quaternion
from facedyn.sim import layout


def _gauss_legendre():
    """Two-stage Gauss-Legendre: nodes c, and from the eigen-decomposition of its Butcher
    matrix A = T diag(lambda, conj lambda) T^-1 the pieces that reduce a step to one
    complex system for W = (T^-1 Z)_1: (I - h lambda J) W = h lambda sum_j S_j G_j, stage
    increments Z_j = 2 Re(T_j W), and y_{n+1} = y_n + sum_j D_j Z_j."""
    a = np.array([[0.25, 0.25 - np.sqrt(3) / 6], [0.25 + np.sqrt(3) / 6, 0.25]])
    eig, vec = np.linalg.eig(a)
    k = int(np.argmax(eig.imag))  # lambda = 1/4 + i sqrt(3)/12
    c = np.array([0.5 - np.sqrt(3) / 6, 0.5 + np.sqrt(3) / 6])
    return c, complex(eig[k]), vec[:, k], np.linalg.inv(vec)[k], np.array([0.5, 0.5]) @ np.linalg.inv(a)


_GL_C, _GL_LAMBDA, _GL_T, _GL_S, _GL_D = _gauss_legendre()


def _stage_predictor() -> tuple[np.ndarray, np.ndarray]:
    """(P, Q), each (2, 2): predict the next step's stages from this step's accelerations.

    The acceleration is extrapolated linearly from this step's two stages (at c_i - 1 in
    the next step's time, units of h); integrated once (Q) and twice (P) from the step
    start to c_j: v(c_j) ~ v + h Q @ acc, u(c_j) ~ u + c_j h v + h^2 P @ acc. Its u is
    fourth-order accurate, ten times closer than extrapolating the stage polynomial.
    """
    t1, t2 = _GL_C - 1.0
    slope = np.array([1.0 / (t1 - t2), 1.0 / (t2 - t1)])  # l_i(t) = slope_i t + offset_i
    offset = np.array([-t2 / (t1 - t2), -t1 / (t2 - t1)])
    c = _GL_C[:, None]
    return slope * c**3 / 6 + offset * c**2 / 2, slope * c**2 / 2 + offset * c


_GL_P, _GL_Q = _stage_predictor()

SAG_BLOCK = 32  # distinct expressions solved together for the gravity sag



class SimulationDiverged(FacedynError):
    """A simulation that blew up: the motion or the expression asks more of the step than it can integrate (a user's
    input, e.g. an extreme BVH, reported in one line, not a bug)."""


class _Diverged(Exception):
    """The integration left the tissue at `frame` (u beyond MAX_DEFLECTION_CM or the face's size, or not a number):
    retried with smaller steps."""

    def __init__(self, frame: int):
        super().__init__(frame)
        self.frame = frame


# The stability bound of the explicit gain-drift correction: the stiffness it adds, per unit
# mass along the spring's stiffest direction, times h^2, must stay below this. Above it the
# correction at predicted stages feeds back into the next step (explicit stiffness is stable
# only while h^2 k is of order one) and, on springs stiff along the normal (160-200 Hz), a
# correction that lasts, as a Live Link curve's small ceaseless changes keep it, grows
# without bound. 1 keeps the built-in face's dialog takes at their factorization count
# (163 on apfel under walking) or a few more (33 -> 43 on alex_rom_4 standing still).
EXPLICIT_LIMIT = 1.0
# No vertex of a face's tissue moves this far from its bone: soft tissue lies 0.3-3 cm deep
# (TissueParams.random), and the standard protocol's 72 dialog takes on a 2.7k-point ARKit
# test rig peak at 3.1 cm (running, hopping). A vertex beyond it is a numerical spike: a
# stiff mode that Gauss-Legendre does not damp, excited by the expression's inertia (one
# vertex of apfel under walking rang to 13.8 cm at one step per frame, 0.9 cm at two).
MAX_DEFLECTION_CM = 5.0
MAX_SUBSTEPS = 16  # the finest step a diverging take is retried at, per frame (1/1920 s at 120 fps)


def substep_ladder(first: int, finest: int = MAX_SUBSTEPS) -> list[int]:
    """Steps per frame to try: as asked, then doubled up to `finest` (or the asked, if finer).

    The explicit parts of a step (the loads on u, u' and the stiffness drift, at stages
    predicted from the step before) are stable only while h^2 times the stiffness they
    meet stays small; Gauss-Legendre does not damp stiff modes (|R(z)| -> 1 as z -> -inf),
    so an error fed into one persists. Halving h quarters that product: a take that
    diverges is simulated again at twice the steps per frame, from the start.
    """
    ladder = [first]
    while ladder[-1] * 2 <= max(finest, first):
        ladder.append(ladder[-1] * 2)
    return ladder


SOFT_HZ = (5.0, 9.0)  # the training family's soft tissue frequencies (TissueParams.random)


def check_band(band) -> tuple[float, float]:
    """(low, high) Hz of a frequency band to draw from, checked."""
    low, high = (float(v) for v in band)
    if not (np.isfinite(low) and np.isfinite(high) and 0 < low <= high):
        raise ValueError(f"a frequency band needs 0 < low <= high Hz, got {low:g}-{high:g}")
    return low, high


@dataclass(frozen=True)
class TissueParams:
    """Physical and numerical constants of the tissue model (cm, s, Hz).

    Only frequencies and lengths: a uniform areal density cancels (every load is
    inertial); its layout does not (heavier skin is held less by the membrane).
    The defaults give the paper's magnitudes: on the ICT face about 5 mm peak offsets on
    an 11 Hz platform of 2 mm amplitude and about 2 mm when walking (0.4-0.5 g vertical
    head acceleration at 2 Hz); ring-downs lose 90 % within about 0.2 s.
    """

    soft_hz: float = 8.0  # natural frequency of free soft tissue (rigid weight 0)
    bone_hz: float = 40.0  # natural frequency of tissue on the bone (rigid weight -> 1)
    damping_ratio: float = 0.25  # Rayleigh damping ratio at soft_hz and at bone_hz
    coupling_cm: float = 1.0  # membrane coupling length: c = coupling_cm * 2 pi soft_hz
    strain_stiffening: float = 4.0  # stiffness gain per unit |strain| of the expression
    gravity_cm_s2: float = 981.0  # world gravity (-Y); 0 leaves gravity out
    substeps: int = 1  # Gauss-Legendre steps per output frame (the first tried: a diverging take is retried finer)
    refactor_tolerance: float = 0.05  # relative change of the system's diagonal that refactorizes
    # spatial layouts (facedyn.sim.layout): log-sd of the bone springs' stiffness and of the
    # areal density over the face, drawn from layout_seed (0: uniform tissue)
    stiffness_variation: float = 0.0
    density_variation: float = 0.0
    layout_seed: int = 0
    # the soft tissue's depth over the face: exp(-depth_variation * t), t in (0, 1) a smooth
    # random layout; a shear layer rings as 1 / depth, so the spring frequency rises by exp(depth_variation * t)
    depth_variation: float = 0.0
    expression_inertia: float = 0.0  # share of the expression's acceleration y'' that loads the tissue (0..1)
    normal_ratio: float = 1.0  # bone spring frequency along the neutral's normal / along the skin (>= 1)

    def __post_init__(self) -> None:
        for name in ("soft_hz", "bone_hz", "damping_ratio", "coupling_cm", "refactor_tolerance"):
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"TissueParams.{name} must be positive, got {value}")
        if self.bone_hz < self.soft_hz:
            raise ValueError(f"TissueParams.bone_hz ({self.bone_hz}) must be >= soft_hz ({self.soft_hz})")
        for name in ("strain_stiffening", "gravity_cm_s2", "stiffness_variation", "density_variation", "depth_variation"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"TissueParams.{name} must be >= 0, got {value}")
        if not np.isfinite(self.normal_ratio) or self.normal_ratio < 1.0:
            raise ValueError(f"TissueParams.normal_ratio must be >= 1, got {self.normal_ratio}")
        if not 0.0 <= self.expression_inertia <= 1.0:
            raise ValueError(f"TissueParams.expression_inertia must be in [0, 1], got {self.expression_inertia}")
        if int(self.substeps) != self.substeps or self.substeps < 1:
            raise ValueError(f"TissueParams.substeps must be a positive integer, got {self.substeps}")

    @classmethod
    def random(cls, seed: int, soft_hz: tuple[float, float] = SOFT_HZ, **overrides) -> "TissueParams":
        """A training actor's tissue drawn from `seed`: soft_hz in the `soft_hz` band (5-9 Hz), bone_hz 30-50 Hz,
        damping ratio 0.15-0.35, coupling 0.6-1.4 cm, strain stiffening 1-6, spatial
        layouts of stiffness (log-sd 0.05-0.3) and density (0-0.2), a depth layout
        (depth_variation 0-1.6), expression inertia 0-1 and normal_ratio 1-4. `overrides`
        replace drawn fields (e.g. substeps). A narrower `soft_hz` band draws the same
        actors otherwise (one uniform draw, mapped into the band).

        Why the last three ranges: facial soft tissue is 1.5-3 cm deep over the cheeks and
        under the jaw but 0.3-0.6 cm over the brow, nose and chin, so the part of the face
        that is free of the bone does not ring at one frequency: a shear layer's frequency
        goes as 1 / depth, up to about 5x (exp(1.6)) the deepest tissue's where it is
        thin. A uniform soft region (depth_variation 0) is the softest actor the family
        holds, not its only one. Tissue moved by the expression carries its own inertia
        unless the muscles that move it hold it (see the module), anything in between.
        Soft tissue is nearly incompressible (Poisson's ratio 0.45-0.5): a layer's
        compression mode rings sqrt(2 (1 - nu) / (1 - 2 nu)) = 3.3x (nu = 0.45) or more
        above its shear mode, less where fat bulges sideways, so the skin moves along the
        bone more than into it: normal_ratio 1 (isotropic) to 4.
        """
        rng = np.random.default_rng([int(seed), 0x746973])  # "tis": another stream than the volumetric draws
        drawn = dict(
            soft_hz=rng.uniform(*check_band(soft_hz)), bone_hz=rng.uniform(30.0, 50.0), damping_ratio=rng.uniform(0.15, 0.35),
            coupling_cm=rng.uniform(0.6, 1.4), strain_stiffening=rng.uniform(1.0, 6.0),
            stiffness_variation=rng.uniform(0.05, 0.3), density_variation=rng.uniform(0.0, 0.2),
            depth_variation=rng.uniform(0.0, 1.6), expression_inertia=rng.uniform(0.0, 1.0),
            normal_ratio=rng.uniform(1.0, 4.0),
        )
        return cls(**{**{k: float(v) for k, v in drawn.items()}, "layout_seed": int(seed), **overrides})

    def rayleigh(self) -> tuple[float, float]:
        """(a, b) of C = a M + b K_0 giving damping_ratio at soft_hz and at bone_hz."""
        w1, w2 = 2 * np.pi * self.soft_hz, 2 * np.pi * self.bone_hz
        return 2 * self.damping_ratio * w1 * w2 / (w1 + w2), 2 * self.damping_ratio / (w1 + w2)

    def attachment_hz(self, rigid_weights: np.ndarray, points: np.ndarray | None = None) -> np.ndarray:
        """Per-vertex spring frequency, geometric from the soft tissue's (weight 0: soft_hz,
        raised where the depth layout thins it) to bone_hz (1), times the stiffness
        layout's factor at the neutral `points` (needed when either layout varies)."""
        weights = np.asarray(rigid_weights, dtype=np.float64)
        soft = self.soft_hz * self._thinning(points)
        hz = soft * (self.bone_hz / soft) ** weights
        return hz * np.sqrt(self._layout(points, "stiffness_variation", layout.STIFFNESS))

    def _thinning(self, points) -> np.ndarray | float:
        """The soft frequency's factor exp(depth_variation * t), t = (1 + tanh(field)) / 2."""
        if self.depth_variation == 0:
            return 1.0
        if points is None:
            raise ValueError("TissueParams.depth_variation > 0 needs the neutral points to lay the tissue out over")
        field = layout.smooth_layout(points, self.layout_seed, layout.DEPTH)
        return np.exp(self.depth_variation * 0.5 * (1.0 + np.tanh(field)))

    def density(self, points: np.ndarray) -> np.ndarray:
        """(N,) relative areal density at the neutral points (1 without a density layout)."""
        return self._layout(points, "density_variation", layout.DENSITY)

    def _layout(self, points, field: str, salt: int) -> np.ndarray | float:
        variation = getattr(self, field)
        if variation == 0:
            return 1.0
        if points is None:
            raise ValueError(f"TissueParams.{field} > 0 needs the neutral points to lay the tissue out over")
        return np.exp(variation * layout.smooth_layout(points, self.layout_seed, salt))


@dataclass
class SimulationResult:
    """A simulated take in skull space. The noise-free truth is ``rest_shapes + offsets``."""

    points: np.ndarray  # (F, N, 3) y + u, plus tracking noise when asked for
    offsets: np.ndarray  # (F, N, 3) u, the whole deflection from y: dynamics + gravity sag
    gravity_sag: np.ndarray  # (F, N, 3) s, the static sag of the pose (see the module)
    stiffness_gain: np.ndarray  # (F, N) s_i(t) = 1 + strain_stiffening * |strain|
    attachment_hz: np.ndarray  # (N,) spring frequency of each vertex
    factorizations: int  # sparse factorizations the run needed
    substeps: int = 1  # steps per frame the integration took (more than asked when it had to retry)

    @property
    def dynamics(self) -> np.ndarray:
        """(F, N, 3) u - s: the true secondary dynamics, what motion adds to the pose's shape."""
        return self.offsets - self.gravity_sag


def simulate(
    rest_shapes: np.ndarray,
    triangles: np.ndarray,
    skull_translate: np.ndarray,
    skull_orient: np.ndarray,
    fps: float,
    params: TissueParams | None = None,
    noise_cm: float = 0.0,
    seed: int = 0,
    *,
    rigid_weights: np.ndarray | None = None,
    neutral: np.ndarray | None = None,
    max_substeps: int = MAX_SUBSTEPS,
) -> SimulationResult:
    """Add physically simulated secondary dynamics to a quasistatic skin sequence.

    rest_shapes: (F, N, 3) y(t) in skull space; triangles: (T, 3) vertex indices;
    skull_translate (F, 3) and skull_orient (F, 4, w x y z) map skull to world space;
    fps > 0. rigid_weights (N,) in [0, 1] (default all 0, soft; 1 = held on the bone);
    neutral (N, 3) is the unstrained shape (default rest_shapes[0]). noise_cm adds seeded
    Gaussian tracking noise (per coordinate) to ``points`` only. The tissue is at rest at
    frame 0, sagging as the rest shape says for frame 0's orientation (gravity acts as
    it turns away from it). Float32 input gives float32 output. A run that diverges is
    integrated again at twice the steps per frame, up to `max_substeps` (`substep_ladder`).
    """
    params = TissueParams() if params is None else params
    y, tri, translate, orient, weights, neutral = validate_inputs(
        rest_shapes, triangles, skull_translate, skull_orient, fps, rigid_weights, neutral, noise_cm)
    frames, n = y.shape[:2]
    dtype = np.result_type(y.dtype, np.float32)
    free = np.flatnonzero(weights < 1.0)
    gain = _stiffness_gain(y, neutral, tri, params.strain_stiffening)
    hz = params.attachment_hz(weights, neutral)
    offsets = np.zeros((frames, n, 3), dtype=dtype)
    sag = np.zeros((frames, n, 3), dtype=dtype)
    factorizations = 0
    substeps = params.substeps
    if frames > 1 and free.size:
        skull = SkullMotion(translate, orient, fps, params.gravity_cm_s2)
        turned = skull.gravity_change(orient)
        limit = min(MAX_DEFLECTION_CM, float(np.ptp(neutral, axis=0).max()))  # beyond it (or the face's size): no tissue
        with single_threaded_blas():
            for substeps in substep_ladder(params.substeps, max_substeps):
                tissue = _Tissue(neutral, tri, free, hz[free], params, 1.0 / (fps * substeps))
                try:
                    factorizations += tissue.run(y, gain, skull, fps, substeps, offsets, limit)
                    break
                except _Diverged as diverged:
                    frame = diverged.frame
            else:
                raise SimulationDiverged(
                    f"the spring tissue diverged at frame {frame} ({frame / fps:.2f} s) even at {substeps} steps per frame: the "
                    "skull's accelerations or the expression's changes there are beyond what a face's tissue undergoes")
            if np.any(turned):
                sag[:, free] = tissue.gravity_sag(gain[:, free], turned)
    points = y + offsets
    if noise_cm > 0:
        points += np.random.default_rng(seed).normal(0.0, noise_cm, points.shape).astype(dtype)
    return SimulationResult(points.astype(dtype, copy=False), offsets, sag, gain, hz, factorizations, substeps)


def validate_inputs(rest_shapes, triangles, translate, orient, fps, weights, neutral, noise_cm):
    """`simulate`'s arguments checked and normalized (shared by every physics of facedyn.sim):
    (y, int64 triangles, float64 translate, continuous orient, rigid weights, neutral)."""
    y = np.asarray(rest_shapes)
    if y.ndim != 3 or y.shape[2] != 3 or y.shape[0] < 1 or not np.issubdtype(y.dtype, np.floating):
        raise ValueError(f"rest_shapes must be (frames, points, 3) floats, got {y.shape} {y.dtype}")
    frames, n = y.shape[:2]
    tri = np.asarray(triangles)
    if tri.ndim != 2 or tri.shape[1] != 3 or not np.issubdtype(tri.dtype, np.integer):
        raise ValueError(f"triangles must be (T, 3) integer indices, got {tri.shape} {tri.dtype}")
    if tri.size and (tri.min() < 0 or tri.max() >= n):
        raise ValueError(f"triangle indices must lie in [0, {n}), got [{tri.min()}, {tri.max()}]")
    translate = np.asarray(translate, dtype=np.float64)
    orient = np.asarray(orient, dtype=np.float64)
    if translate.shape != (frames, 3):
        raise ValueError(f"skull_translate must be ({frames}, 3) to match rest_shapes, got {translate.shape}")
    if orient.shape != (frames, 4):
        raise ValueError(f"skull_orient must be ({frames}, 4) quaternions (w, x, y, z), got {orient.shape}")
    if not np.isfinite(fps) or fps <= 0:
        raise ValueError(f"fps must be positive, got {fps}")
    weights = np.zeros(n) if weights is None else np.asarray(weights, dtype=np.float64)
    if weights.shape != (n,):
        raise ValueError(f"rigid_weights must be ({n},), got {weights.shape}")
    if not np.all((weights >= 0) & (weights <= 1)):
        raise ValueError("rigid_weights must lie in [0, 1]")
    neutral = np.asarray(y[0] if neutral is None else neutral, dtype=np.float64)
    if neutral.shape != (n, 3):
        raise ValueError(f"neutral must be ({n}, 3), got {neutral.shape}")
    if not np.isfinite(noise_cm) or noise_cm < 0:
        raise ValueError(f"noise_cm must be >= 0, got {noise_cm}")
    arrays = {"rest_shapes": y, "skull_translate": translate, "skull_orient": orient, "neutral": neutral}
    for name, arr in arrays.items():
        if not np.isfinite(np.sum(arr, dtype=np.float64)):  # a sum: no take-sized temporary
            raise ValueError(f"{name} holds non-finite values")
    if np.any(np.linalg.norm(orient, axis=1) < 1e-12):
        raise ValueError("skull_orient holds a zero quaternion")
    return y, tri.astype(np.int64), translate, quaternion.make_continuous(orient), weights, neutral


def _stiffness_gain(y: np.ndarray, neutral: np.ndarray, tri: np.ndarray, stiffening: float) -> np.ndarray:
    """(F, N) 1 + stiffening * mean |l(t) / l_neutral - 1| over each vertex's edges.

    Only frames that differ from their predecessor are measured (held expressions are
    common); the edge vectors of a chunk of frames come from one float32 sparse product.
    """
    frames, n = y.shape[:2]
    edges = mesh.unique_edges(tri)
    rest = np.linalg.norm(neutral[edges[:, 1]] - neutral[edges[:, 0]], axis=1)
    edges, rest = edges[rest > 0], rest[rest > 0]
    if stiffening == 0 or not len(edges):
        return np.ones((frames, n), dtype=np.float32)
    count = len(edges)
    ids = np.tile(np.arange(count), 2)
    signs = np.repeat(np.float32([1.0, -1.0]), count)
    difference = sp.csr_matrix((signs, (ids, edges.T[::-1].ravel())), shape=(count, n))
    incidence = abs(difference).T.tocsr()
    degree = np.maximum(np.asarray(incidence.sum(axis=1)).ravel(), 1.0)
    average = (sp.diags(stiffening / degree) @ incidence).astype(np.float32).tocsr()
    inverse = (1.0 / rest).astype(np.float32)[:, None]
    new = np.ones(frames, dtype=bool)
    for first in range(1, frames, 256):  # in chunks: a long take's comparison is big
        stop = min(first + 256, frames)
        new[first:stop] = np.any(y[first:stop] != y[first - 1:stop - 1], axis=(1, 2))
    keys = np.flatnonzero(new)
    measured = np.empty((len(keys), n), dtype=np.float32)
    chunk = max(1, 4_000_000 // (3 * count))
    for first in range(0, len(keys), chunk):
        yc = np.asarray(y[keys[first:first + chunk]], dtype=np.float32)
        c = len(yc)
        vectors = difference @ yc.transpose(1, 2, 0).reshape(n, 3 * c)  # (E, [x, y, z] x frames)
        strain = vectors[:, :c] ** 2 + vectors[:, c:2 * c] ** 2 + vectors[:, 2 * c:] ** 2
        np.sqrt(strain, out=strain)
        strain *= inverse
        strain -= 1.0
        np.abs(strain, out=strain)
        measured[first:first + chunk] = (average @ strain).T
    measured += 1.0
    return measured if new.all() else measured[np.cumsum(new) - 1]


class SkullMotion:
    """C2 interpolation of the sampled skull motion and its loads in skull axes.

    Translation and (sign-continuous) quaternion components are cubic splines, so the
    inertial loads are continuous between frames; the body angular velocity is
    2 Im(conj(q) q') / |q|^2, exact for the interpolated (not necessarily unit) q.
    """

    def __init__(self, translate: np.ndarray, orient: np.ndarray, fps: float, gravity: float):
        times = np.arange(len(translate)) / fps
        self._translate = CubicSpline(times, translate, axis=0)
        self._orient = CubicSpline(times, orient, axis=0)
        self._gravity = np.array([0.0, -gravity, 0.0])
        self._gravity_ref = self._linear(orient[:1], np.zeros((1, 3)))[0]

    def _linear(self, q: np.ndarray, acceleration: np.ndarray) -> np.ndarray:
        """Gravity minus the origin's acceleration, world (T, 3) -> skull axes."""
        rot_t = np.swapaxes(quaternion.to_matrix(q), 1, 2)
        return (rot_t @ (self._gravity - acceleration)[:, :, None])[:, :, 0]

    def gravity_change(self, orient: np.ndarray) -> np.ndarray:
        """(F, 3) g(t) - g(0) in skull axes at the sampled orientations."""
        return self._linear(orient, np.zeros((len(orient), 3))) - self._gravity_ref

    def loads(self, times: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """At `times`: (g - g(0) - a0, omega, alpha), each (T, 3) in skull axes."""
        q, dq, ddq = self._orient(times), self._orient(times, 1), self._orient(times, 2)
        norm2 = np.sum(q * q, axis=1, keepdims=True)
        conj = quaternion.conjugate(q)
        omega = 2 * quaternion.multiply(conj, dq)[:, 1:] / norm2
        growth = 2 * np.sum(q * dq, axis=1, keepdims=True) / norm2  # d|q|^2/dt / |q|^2
        alpha = 2 * quaternion.multiply(conj, ddq)[:, 1:] / norm2 - omega * growth
        linear = self._linear(q, self._translate(times, 2)) - self._gravity_ref
        return linear, omega, alpha


def _cross_matrices(w: np.ndarray) -> np.ndarray:
    """(..., 3) vectors -> (..., 3, 3) matrices [w]x with [w]x v = w x v."""
    z = np.zeros(w.shape[:-1])
    x, y_, zz = np.moveaxis(w, -1, 0)
    return np.stack([np.stack([z, -zz, y_], -1), np.stack([zz, z, -x], -1), np.stack([-y_, x, z], -1)], -2)


class _Tissue:
    """The free vertices' discrete system and its Gauss-Legendre integration.

    With p = mu sigma v (sigma = S_1 + S_2) and the stage loads, the right-hand side of
    the stage system, (M + mu C) p + mu M q, collapses to
        M (mu sigma v - mu^2 sigma M^-1 K_ref u + mu^2 sum_j S_j load_j)
    (C cancels), and the system is solved divided by M: a step is one small dense product
    (the loads), one sparse product (M^-1 K_ref u) and one complex solve. The loads' terms
    in u and u' (alpha x u, omega x (omega x u), 2 omega x u') and the gain drift use stage
    values predicted from the previous step (`_stage_predictor`), linear in its v and w,
    so they fold into the dense product's weights.
    """

    def __init__(self, neutral, tri, free, hz, params: TissueParams, h: float):
        n = len(neutral)
        mass = mesh.vertex_areas(neutral, tri)
        # Vertices in no triangle have no area; give them a small one so they still move.
        mass = np.maximum(mass, 1e-3 * mass[mass > 0].mean() if np.any(mass > 0) else 1.0) * params.density(neutral)
        lap = mesh.cotangent_laplacian(neutral, tri, nonnegative=True)
        if len(free) < n:
            lap = lap[free][:, free]  # held neighbours have u = 0: only their diagonal pull stays
        self.free = free
        self.mass = mass[free]
        self.spring = (2 * np.pi * hz) ** 2  # w_i^2
        along = mesh.vertex_normals(neutral, tri)[free] if params.normal_ratio > 1 else None
        self.directions = _Directions(along, params.normal_ratio**2 - 1.0)
        self.membrane = ((params.coupling_cm * 2 * np.pi * params.soft_hz) ** 2 * lap).tocsr()
        self.a, self.b = params.rayleigh()
        self.h = h
        self.mu = h * _GL_LAMBDA
        self.tolerance = params.refactor_tolerance
        self.explicit_weight = h * h * self.spring * (1.0 + self.directions.extra)  # h^2 k per unit gain drift (EXPLICIT_LIMIT)
        self.inertia = params.expression_inertia

    def gravity_sag(self, gain: np.ndarray, turned: np.ndarray, tolerance: float = 1e-5) -> np.ndarray:
        """(F, n, 3) static sag s(t) of the free vertices: K(t) s = M (g(t) - g(0)).

        With isotropic springs K(t) = M diag(w^2 gain(t)) + c^2 L scales the same in x, y
        and z, so s(t) = phi(t) (g(t) - g(0)) with K(t) phi = M 1, one scalar field per
        distinct gain row (a held expression has one); with springs stiffer along the
        normal, three fields per row, one per axis of g. Rows go through in time order, SAG_BLOCK at a time
        (SuperLU's solves slow down sharply with many right-hand sides): conjugate
        gradients preconditioned with K factorized at the block's mean gain, which
        consecutive frames stay close to (K is SPD; only its diagonal follows the
        expression), to a residual of `tolerance` relative to M 1.
        """
        _, first, which = np.unique(gain, axis=0, return_index=True, return_inverse=True)
        order = np.argsort(first)  # distinct rows in the order the take reaches them
        rank = np.empty_like(order)
        rank[order] = np.arange(len(order))
        rows = gain[np.sort(first)]
        row_of_frame = rank[which.ravel()]
        base = self.mass * self.spring
        directions = self.directions
        out = np.empty((len(gain), len(base), 3))
        limit = tolerance * np.linalg.norm(self.mass)
        for a in range(0, len(rows), SAG_BLOCK):
            block = rows[a:a + SAG_BLOCK]
            reference = block.mean(axis=0)
            matrix = (directions.springs(base * reference) + directions.expand(self.membrane)).tocsc()
            lu = spla.splu(matrix, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})  # SPD
            beyond = (base[None, :] * (block - reference)).T  # (n, G): the springs beyond the reference

            def stiffer(x):
                return directions.scale(beyond, x)

            b = directions.unit_loads(self.mass, len(block))
            x = lu.solve(b)
            r = b - (matrix @ x + stiffer(x))
            z = lu.solve(r)
            p, rz = z.copy(), np.sum(r * z, axis=0)
            for _ in range(200):
                if np.sqrt(np.sum(r * r, axis=0)).max() <= limit:
                    break
                q = matrix @ p + stiffer(p)
                alpha = rz / np.sum(p * q, axis=0)
                x += alpha * p
                r -= alpha * q
                z = lu.solve(r)
                rz, previous = np.sum(r * z, axis=0), rz
                p = z + (rz / previous) * p
            frames = np.flatnonzero((row_of_frame >= a) & (row_of_frame < a + len(block)))
            out[frames] = directions.sag(x, row_of_frame[frames] - a, turned[frames])
        return out

    def _factorize(self, gain_ref: np.ndarray):
        """At gain_ref: LU of M^-1 (M + mu C + mu^2 K), M^-1 K, and each vertex's
        sensitivity to gain drift (the share of its diagonal that the gain scales).
        Dividing by the masses saves a product per step; the sparsity stays symmetric."""
        mu, spring, scale, directions = self.mu, self.spring, sp.diags(1.0 / self.mass), self.directions
        coupling = scale @ self.membrane
        matrix = (directions.identity(len(spring)) * (1 + mu * self.a) + directions.springs((mu * self.b + mu * mu * gain_ref) * spring)
                  + (mu * self.b + mu * mu) * directions.expand(coupling)).tocsc()
        # relax=1 (no padded supernodes): the padding costs the 3-column solves ~15 %
        lu = spla.splu(matrix, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, relax=1,
                       options={"SymmetricMode": True})
        stiffness = (directions.expand(coupling) + directions.springs(spring * gain_ref)).tocsr()
        # the drift's share of the isotropic diagonal, along the stiffest direction (the normal): the
        # correction is explicit, so a stiffer normal spring must drift less before refactorizing
        full = (1 + mu * self.a) + (mu * self.b + mu * mu * gain_ref) * spring + (mu * self.b + mu * mu) * coupling.diagonal()
        return lu, stiffness, np.abs(mu * mu * spring * (1.0 + directions.extra)) / np.abs(full)

    def _step_maps(self):
        """A step's linear maps, each coefficient c acting as 'c v' (real) or '2 Re(c w)':
        u_new = u + 2 Re(tau w), v_new = v_keep v + 2 Re(tau_v w), and the next step's
        predicted stage increments (`_stage_predictor`) du_j = du_v[j] v_new + 2 Re(du_w[j] w),
        dv_j = dv_v[j] v_new + 2 Re(dv_w[j] w). The stage accelerations it needs,
        2 Re(T_i w / mu^2) + acc_v_i v_old, are rewritten in v_new (v_old = (v_new -
        2 Re(tau_v w)) / v_keep), so nothing but v and w is carried between steps."""
        h, mu, sigma = self.h, self.mu, _GL_S.sum()
        tau = _GL_D @ _GL_T
        tau_v, v_keep = tau / mu, 1.0 - 2 * (tau * sigma).real
        acc_w, acc_v = _GL_T / mu**2, -2 * (_GL_T * sigma / mu).real
        pw, pv = h * h * _GL_P @ acc_w, h * h * _GL_P @ acc_v
        qw, qv = h * _GL_Q @ acc_w, h * _GL_Q @ acc_v
        du_v, du_w = _GL_C * h + pv / v_keep, pw - pv * tau_v / v_keep
        dv_v, dv_w = qv / v_keep, qw - qv * tau_v / v_keep
        return tau, tau_v, v_keep, du_v, du_w, dv_v, dv_w

    def _rhs_weights(self, frac, linear, omega, alpha, fps):
        """(steps, 22, 6) real weights W such that x @ W[step] = [Re, Im] of the step's
        right-hand side mu sigma v - mu^2 sigma M^-1 K u + mu^2 sum_j S_j load_j, for
        x = [y_f, dy, u, v, Re w_prev, Im w_prev, M^-1 K u, 1] (y_f: the rest shape at the
        frame start, dy: its change over the frame); the loads see each stage's predicted
        u and u'."""
        mu, eye = self.mu, np.eye(3)
        gamma, c_k = mu * mu * _GL_S, mu * mu * _GL_S.sum()
        wx = _cross_matrices(omega)  # (steps, 2, 3, 3)
        rot = -(_cross_matrices(alpha) + wx @ wx)
        # row-vector form, load[c'] = sum_c x[c] A[c, c']: weights of the position, the velocity
        pos = gamma[None, :, None, None] * np.swapaxes(rot, -1, -2)
        vel = gamma[None, :, None, None] * np.swapaxes(-2 * wx, -1, -2)
        du_v, du_w, dv_v, dv_w = (c[None, :, None, None] for c in self._step_maps()[3:])
        steps = len(frac)
        blocks = np.stack([
            pos.sum(1),
            (frac[:, :, None, None] * pos + fps * vel).sum(1),
            pos.sum(1),
            (du_v * pos + (1 + dv_v) * vel).sum(1) + mu * _GL_S.sum() * eye,
            (2 * du_w.real * pos + 2 * dv_w.real * vel).sum(1),
            (-2 * du_w.imag * pos - 2 * dv_w.imag * vel).sum(1),
            np.broadcast_to(-c_k * eye, (steps, 3, 3)),
        ], axis=1)  # (steps, 7, 3, 3)
        constants = (gamma[None, :, None] * linear).sum(1)
        return np.concatenate([
            np.concatenate([blocks.real, blocks.imag], axis=-1).reshape(steps, 21, 6),
            np.concatenate([constants.real, constants.imag], axis=1)[:, None, :],
        ], axis=1)

    def _state_maps(self):
        """advance (12, 6): [u, v, Re w, Im w] -> the new [u, v]; predict (12, 6): the same
        blocks after the step -> the next step's predicted u at stages 1 and 2."""
        eye = np.eye(3)
        tau, tau_v, v_keep, du_v, du_w = self._step_maps()[:5]
        advance = np.block([
            [eye, 0 * eye], [0 * eye, v_keep * eye],
            [2 * tau.real * eye, 2 * tau_v.real * eye], [-2 * tau.imag * eye, -2 * tau_v.imag * eye],
        ])
        predict = np.concatenate([np.concatenate([eye, du_v[j] * eye, 2 * du_w[j].real * eye,
                                                  -2 * du_w[j].imag * eye]) for j in range(2)], axis=1)
        return advance, predict

    def run(self, y, gain, skull: SkullMotion, fps: float, substeps: int, out: np.ndarray, limit: float = np.inf) -> int:
        """Integrate from rest and write u of the free vertices into out (F, N, 3).

        Returns the number of factorizations. The gain drift is only measured on frames
        whose gain changes or while the factorized gain differs from the current one.
        Raises _Diverged at the first frame whose |u| exceeds `limit` (or is not a number).
        """
        frames, n, free = len(y), len(self.free), self.free
        every = n == y.shape[1]
        steps = (frames - 1) * substeps
        frac = (np.arange(steps)[:, None] % substeps + _GL_C[None, :]) / substeps  # stage times in the frame
        start = np.arange(steps) // substeps
        linear, omega, alpha = (x.reshape(steps, 2, 3) for x in skull.loads((start[:, None] + frac).ravel() / fps))
        weights = self._rhs_weights(frac, linear, omega, alpha, fps)
        advance, predict = self._state_maps()
        gamma = self.mu**2 * _GL_S
        moving = np.any(gain[1:] != gain[:-1], axis=1)
        # -e y'' at the stages, linear between the frames' y'': weights of the frame start's and end's
        inertia = (-self.inertia * gamma * (1 - frac)).sum(1), (-self.inertia * gamma * frac).sum(1)
        acceleration = _FrameAccelerations(y, None if every else free, fps)

        x = np.zeros((n, 22))  # [y_f, dy, u, v, Re w, Im w, M^-1 K u, 1], see _rhs_weights
        x[:, 21] = 1.0
        u = x[:, 6:9]
        rhs = np.empty((n, 3), dtype=complex, order="F")
        parts = rhs.T.view(np.float64).reshape(3, n, 2)  # [coordinate, vertex, Re/Im] of rhs
        gain_ref = gain[0, free]
        lu, stiffness, sensitivity = self._factorize(gain_ref)
        factorizations, at_ref = 1, True
        y_next = y[0] if every else y[0, free]
        for step in range(steps):
            f = start[step]
            if step % substeps == 0:
                y_now, y_next = y_next, (y[f + 1] if every else y[f + 1, free])
                x[:, :3] = y_now
                np.subtract(y_next, y_now, out=x[:, 3:6])
                if self.inertia:
                    acc_now, acc_next = acceleration(f), acceleration(f + 1)
            drift = 0.0
            if moving[f] or not at_ref:
                g_now = gain[f, free]
                change = gain[f + 1, free] - g_now
                reach = np.abs(g_now - gain_ref) + frac[step].max() * np.abs(change)
                drift = float(np.max(sensitivity * reach))
                explicit = float(np.max(self.explicit_weight * reach))
                # refactorize for accuracy (drift), for stability (explicit), and once for a held expression, whose lasting
                # correction grows on springs stiffer along the normal
                if (drift > self.tolerance or explicit > EXPLICIT_LIMIT
                        or (drift > 0 and self.directions.normals is not None and not moving[f])):
                    gain_ref = g_now + frac[step].mean() * change
                    lu, stiffness, sensitivity = self._factorize(gain_ref)
                    factorizations += 1
                at_ref = not moving[f] and not np.any(g_now != gain_ref)
            x[:, 18:21] = self.directions.apply(stiffness, u)
            np.copyto(parts, (x @ weights[step]).reshape(n, 2, 3).transpose(2, 0, 1))
            if self.inertia:
                rhs += inertia[0][step] * acc_now + inertia[1][step] * acc_next
            if drift > 0:  # the stiffness the factorization lacks, where it drifted, at the predicted stages
                active = np.flatnonzero(reach)
                stages = x[active, 6:18] @ predict
                pull = -self.spring[active] * (g_now - gain_ref)[active]
                slope = -self.spring[active] * change[active]
                extra = sum(self.directions.oriented(gamma[j] * (pull + frac[step, j] * slope), stages[:, 3 * j:3 * j + 3], active)
                            for j in range(2))
                rhs[active] += extra
            w = self.directions.apply(lu.solve, rhs)
            x[:, 12:15], x[:, 15:18] = w.real, w.imag
            x[:, 6:12] = x[:, 6:18] @ advance
            if (step + 1) % substeps == 0:
                if not np.abs(u).max() <= limit:  # checked every frame: a diverging take stops at once
                    raise _Diverged(f + 1)
                if every:
                    out[f + 1] = u
                else:
                    out[f + 1, free] = u
        return factorizations


class _Directions:
    """How the bone springs act on x, y and z: alike (isotropic: every operator is one of the
    n vertices, applied to the three coordinates as columns) or stiffer along each vertex's
    normal by 1 + extra (A_i = I + extra n_i n_i^T: operators of all 3n coordinates, vertex-major)."""

    def __init__(self, normals: np.ndarray | None, extra: float):
        self.normals = normals  # (n, 3) unit normals, None when isotropic
        self.extra = extra if normals is not None else 0.0

    def identity(self, count: int) -> sp.spmatrix:
        return sp.identity(count if self.normals is None else 3 * count, format="csr")

    def expand(self, matrix: sp.spmatrix) -> sp.spmatrix:
        """A coupling between vertices (the membrane) acting on every coordinate alike."""
        return matrix if self.normals is None else sp.kron(matrix, sp.identity(3), format="csr")

    def springs(self, values: np.ndarray) -> sp.spmatrix:
        """diag(values_i A_i): springs of strength values_i per vertex."""
        if self.normals is None:
            return sp.diags(values)
        count = len(values)
        blocks = values[:, None, None] * (np.eye(3) + self.extra * self.normals[:, :, None] * self.normals[:, None, :])
        index = 3 * np.arange(count)[:, None, None] + np.arange(3)
        rows, cols = np.broadcast_to(np.swapaxes(index, 1, 2), blocks.shape), np.broadcast_to(index, blocks.shape)
        return sp.csr_matrix((blocks.ravel(), (rows.ravel(), cols.ravel())), shape=(3 * count, 3 * count))

    def apply(self, operator, vectors: np.ndarray) -> np.ndarray:
        """operator (a matrix or a solve) on (n, 3) per-vertex vectors."""
        apply = operator if callable(operator) else operator.__matmul__
        return apply(vectors) if self.normals is None else apply(vectors.reshape(-1)).reshape(vectors.shape)

    def oriented(self, values: np.ndarray, vectors: np.ndarray, vertices: np.ndarray) -> np.ndarray:
        """values_i A_i v_i for (m,) values and (m, 3) vectors at `vertices`."""
        if self.normals is None:
            return values[:, None] * vectors
        n = self.normals[vertices]
        return values[:, None] * (vectors + self.extra * n * np.sum(n * vectors, axis=1, keepdims=True))

    def unit_loads(self, mass: np.ndarray, groups: int) -> np.ndarray:
        """Right-hand sides M 1 per group: (n, G), or (3n, 3G) with one column per group and axis."""
        if self.normals is None:
            return np.repeat(mass[:, None], groups, axis=1)
        loads = np.zeros((len(mass), 3, groups, 3))
        for axis in range(3):
            loads[:, axis, :, axis] = mass[:, None]
        return loads.reshape(3 * len(mass), 3 * groups)

    def scale(self, values: np.ndarray, x: np.ndarray) -> np.ndarray:
        """values[i, g] A_i applied to the columns of group g of x (laid out as `unit_loads`)."""
        if self.normals is None:
            return values * x
        count, groups = values.shape
        x4 = x.reshape(count, 3, groups, 3)
        along = np.einsum("ia,iagc->igc", self.normals, x4)
        return (values[:, None, :, None] * (x4 + self.extra * self.normals[:, :, None, None] * along[:, None])).reshape(x.shape)

    def sag(self, x: np.ndarray, groups: np.ndarray, turned: np.ndarray) -> np.ndarray:
        """(F', n, 3) sag of frames whose gain rows are `groups`, from the unit-load responses x."""
        if self.normals is None:
            return x.T[groups][:, :, None] * turned[:, None, :]
        count = x.shape[0] // 3
        x4 = x.reshape(count, 3, -1, 3)
        return np.einsum("iafc,fc->fia", x4[:, :, groups], turned)


class _FrameAccelerations:
    """y''(f) of the free vertices by central differences of the frames (zero at the ends,
    as the volumetric layer's), the last two kept: a step asks for frames f and f + 1."""

    def __init__(self, y: np.ndarray, free: np.ndarray | None, fps: float):
        self.y, self.free, self.fps2, self.cache = y, free, fps * fps, {}

    def _frame(self, f: int) -> np.ndarray:
        return self.y[f] if self.free is None else self.y[f, self.free]

    def __call__(self, f: int) -> np.ndarray:
        if f not in self.cache:
            if f == 0 or f == len(self.y) - 1:
                value = np.zeros(self._frame(f).shape)
            else:
                value = (self._frame(f + 1) - 2.0 * self._frame(f).astype(np.float64) + self._frame(f - 1)) * self.fps2
            self.cache = {k: v for k, v in self.cache.items() if k >= f - 1}
            self.cache[f] = value
        return self.cache[f]
