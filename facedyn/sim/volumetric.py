"""A second, independent soft-tissue physics: a hyperelastic finite-element layer.

facedyn.sim.tissue (springs to the bone, a membrane, Rayleigh damping, Gauss-Legendre)
makes the training corpora. Figures measured on data from the same model would flatter
anything tuned alongside it, so test takes can come from this model instead, of another
family in every part:

- Geometry: a volumetric layer of linear tetrahedra between the skin and an inward offset
  "skull" surface, `layers` prisms deep. The thickness varies over the face: `thickness_cm`
  where the rig's rigid weight is 0 (cheeks, lips), `bone_thickness_cm` where it is 1
  (forehead, nose bridge), times a smooth random layout, and is shrunk locally where the
  offset would fold (tight curvature: nose, lips).
- Material: stable Neo-Hookean (Smith, de Goes, Kim 2018, rest-stable form) plus a
  stiffening term (mu k / 4) E^2, E = I_C - 3 - 2 (J - 1), which is zero to second order
  at rest (so the rest tangent is plain linear elasticity with the given shear modulus and
  Poisson ratio) and grows as the fourth power of large shear.
- Loads: in the skull frame, the inertial loads of the skull's motion (origin acceleration,
  Euler, Coriolis, centrifugal) and the turn of gravity, on every free node; AND the
  expression's own inertia: the rest configuration X(t) of the layer is the rig's
  quasistatic skin y(t) with the layer's columns hanging under it, and a node's inertial
  load includes -X''(t). The inner surface is attached to the skull (it follows X(t)),
  skin with rigid weight 1 is held on y(t).
- Damping: Kelvin-Voigt material viscosity, viscous stress tau_e times the linear elastic
  stress rate, with its own random spatial layout of tau (so the damping is not
  proportional to the stiffness: non-classical damping); its ratio grows with frequency,
  damping_ratio at soft_hz.
- Integration: Newmark average acceleration (implicit trapezoidal, energy-conserving for
  the linear part, second order), the nonlinear step solved by chord iterations with
  M 4/h^2 + C 2/h + K_ref factorized once (K_ref the linear stiffness at the rest
  configuration, refactorized when the expression's rest shape drifts by more than
  `refactor_strain`).

Natural frequency: the fundamental shear mode of a uniform layer on a rigid base is the
quarter wave f = sqrt(mu / rho) / (4 h); the shear modulus is set from `soft_hz` by its
discrete form at `thickness_cm` (see `VolumetricParams.shear_modulus`), so a flat layer
rings at soft_hz; on the built-in face, whose soft regions are held by thinner tissue
around them, the ring-down peaks about 15 % higher.

Gravity: as in facedyn.sim.tissue, the tissue is at rest at frame 0 as the rest shape says,
gravity acts as it turns away from frame 0's, and `gravity_sag` is the static (nonlinear)
response to that turn, so `dynamics` = offsets - sag is what motion adds.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components

from facedyn.blas import single_threaded_blas
from facedyn.geometry import mesh
from facedyn.sim import layout
from facedyn.sim.tissue import SimulationDiverged, SkullMotion, check_band, substep_ladder, validate_inputs

# A prism (three tetrahedra) thinner than this fraction of its ideal volume counts as folded.
_MIN_QUALITY = 0.2
_SHRINK = 0.8  # thickness factor per folding fix
_CURVATURE_DEPTH = 0.5  # the depth stays under this fraction of the skin's convex radius of curvature
_DEPTH_SLOPE = 0.5  # cm of depth per cm along the skin, at most
_SHRINK_ROUNDS = 12
_MAX_ITERATIONS = 30  # chord iterations per step before the step refactorizes
_SAG_ITERATIONS = 30  # chord iterations of a frame's gravity sag
_NEWTON_ITERATIONS = 30  # Newton steps of a gravity sag where chord iterations did not converge
_MIN_DEPTH = 0.25  # prisms thinner than this fraction of bone_thickness_cm are left out
_SAG_SHIFT_HZ = 0.2  # mass shift of the static preconditioner, far below any tissue mode


@dataclass(frozen=True)
class VolumetricParams:
    """Per-actor material, geometry and numerical constants (cm, g, s, Hz).

    `random(seed)` draws a plausible actor; the *_variation fields are the standard
    deviations of the log of smooth random factors over the face (seeded by layout_seed).
    """

    soft_hz: float = 7.0  # quarter-wave shear frequency of the soft layer (sets the shear modulus)
    thickness_cm: float = 1.8  # soft tissue depth where the rigid weight is 0
    bone_thickness_cm: float = 0.4  # tissue depth over bone (rigid weight -> 1)
    density: float = 1.05  # g / cm^3
    poisson: float = 0.45  # nearly incompressible tissue
    damping_ratio: float = 0.2  # Kelvin-Voigt viscosity: this damping ratio at soft_hz
    nonlinearity: float = 2.0  # k of the stiffening term (mu k / 4) E^2
    stiffness_variation: float = 0.0
    density_variation: float = 0.0
    damping_variation: float = 0.0
    thickness_variation: float = 0.0
    layout_seed: int = 0
    layers: int = 1  # prisms through the depth
    gravity_cm_s2: float = 981.0  # world gravity (-Y); 0 leaves gravity out
    substeps: int = 1  # Newmark steps per output frame
    tolerance_cm: float = 1e-5  # chord iterations stop when no node moves more than this
    refactor_strain: float = 0.1  # rest-shape strain since the factorization that refactorizes

    def __post_init__(self) -> None:
        positive = ("soft_hz", "thickness_cm", "bone_thickness_cm", "density", "damping_ratio", "tolerance_cm", "refactor_strain")
        for name in positive:
            value = getattr(self, name)
            if not np.isfinite(value) or value <= 0:
                raise ValueError(f"VolumetricParams.{name} must be positive, got {value}")
        non_negative = ("nonlinearity", "stiffness_variation", "density_variation", "damping_variation", "thickness_variation", "gravity_cm_s2")
        for name in non_negative:
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise ValueError(f"VolumetricParams.{name} must be >= 0, got {value}")
        if not 0.0 <= self.poisson < 0.5:
            raise ValueError(f"VolumetricParams.poisson must be in [0, 0.5), got {self.poisson}")
        for name in ("layers", "substeps"):
            value = getattr(self, name)
            if int(value) != value or value < 1:
                raise ValueError(f"VolumetricParams.{name} must be a positive integer, got {value}")

    @classmethod
    def random(cls, seed: int, soft_hz: tuple[float, float] = (4.5, 8.0), **overrides) -> "VolumetricParams":
        """An actor drawn from the ranges of issue 18, independent of any TissueParams draw:
        soft_hz in the `soft_hz` band, 4.5-8 Hz (the built-in face rings about 15 % above its layer's soft_hz,
        so 5-9 Hz in effect; tests/sim/test_volumetric.py measures it), soft depth 1.2-2.4 cm, depth over bone 0.3-0.6 cm, density
        0.95-1.1 g/cm^3, Poisson 0.42-0.47, damping ratio 0.12-0.35 at soft_hz,
        nonlinearity 0.5-4, and spatial layouts of stiffness (log-sd 0.1-0.4), density
        (0-0.15), viscosity (0-0.3) and depth (0-0.2). `overrides` replace drawn fields."""
        rng = np.random.default_rng([int(seed), 0x766F6C])  # "vol": another stream than tissue's draws
        drawn = dict(
            soft_hz=rng.uniform(*check_band(soft_hz)), thickness_cm=rng.uniform(1.2, 2.4), bone_thickness_cm=rng.uniform(0.3, 0.6),
            density=rng.uniform(0.95, 1.1), poisson=rng.uniform(0.42, 0.47), damping_ratio=rng.uniform(0.12, 0.35),
            nonlinearity=rng.uniform(0.5, 4.0), stiffness_variation=rng.uniform(0.1, 0.4),
            density_variation=rng.uniform(0.0, 0.15), damping_variation=rng.uniform(0.0, 0.3),
            thickness_variation=rng.uniform(0.0, 0.2), layout_seed=int(seed),
        )
        drawn = {name: float(value) if isinstance(value, np.floating) else value for name, value in drawn.items()}
        return cls(**{**drawn, **overrides})

    @property
    def shear_modulus(self) -> float:
        """Lame shear modulus (g / (cm s^2)) that makes the soft layer ring at soft_hz.

        A layer of depth h on a rigid base, discretized as `layers` shear springs with
        lumped masses (half a mass on the skin), has its fundamental at
        omega = 2 sqrt(mu / rho) (L / h) sin(pi / (4 L)), which tends to the continuum's
        quarter wave (pi / 2h) sqrt(mu / rho) as L grows; solved here for mu.
        """
        reach = 2.0 * self.layers * np.sin(np.pi / (4.0 * self.layers)) / self.thickness_cm
        return self.density * (2.0 * np.pi * self.soft_hz / reach) ** 2

    @property
    def viscosity_time(self) -> float:
        """Kelvin-Voigt retardation time tau (s): damping ratio pi f tau at frequency f."""
        return self.damping_ratio / (np.pi * self.soft_hz)


@dataclass
class VolumetricResult:
    """A simulated take in skull space, shaped like facedyn.sim.tissue.SimulationResult."""

    points: np.ndarray  # (F, N, 3) y + u, plus tracking noise when asked for
    offsets: np.ndarray  # (F, N, 3) u of the skin: dynamics + gravity sag
    gravity_sag: np.ndarray  # (F, N, 3) static sag of the pose
    thickness: np.ndarray  # (N,) tissue depth under each skin vertex (0 where no layer)
    tetrahedra: int  # elements of the layer
    torn: int  # elements left out because the expressions crush them (see Layer)
    factorizations: int
    iterations: int  # chord iterations, all steps together

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
    params: VolumetricParams | None = None,
    noise_cm: float = 0.0,
    seed: int = 0,
    *,
    rigid_weights: np.ndarray | None = None,
    neutral: np.ndarray | None = None,
) -> VolumetricResult:
    """Add the volumetric layer's secondary dynamics to a quasistatic skin sequence.

    The call of facedyn.sim.tissue.simulate: rest_shapes (F, N, 3) y(t) in skull space,
    triangles (T, 3), skull_translate (F, 3) and skull_orient (F, 4, w x y z) map skull to
    world space, rigid_weights (N,) in [0, 1] (1 = held on the bone; they also set the
    depth), neutral (N, 3) the unstrained shape (default rest_shapes[0]). noise_cm adds
    seeded Gaussian noise to ``points`` only. Float32 input gives float32 output.
    """
    params = VolumetricParams() if params is None else params
    y, tri, translate, orient, weights, neutral = validate_inputs(
        rest_shapes, triangles, skull_translate, skull_orient, fps, rigid_weights, neutral, noise_cm)
    frames, n = y.shape[:2]
    dtype = np.result_type(y.dtype, np.float32)
    offsets = np.zeros((frames, n, 3), dtype=dtype)
    sag = np.zeros((frames, n, 3), dtype=dtype)
    layer = Layer(neutral, tri, weights, params, y)
    thickness = np.zeros(n)
    thickness[layer.vertices] = layer.depth
    factorizations = iterations = 0
    if frames > 1 and layer.free.size:
        skull = SkullMotion(translate, orient, fps, params.gravity_cm_s2)
        with single_threaded_blas():
            for substeps in substep_ladder(params.substeps):  # a diverging take is integrated again at finer steps
                try:
                    factorizations, iterations = _integrate(layer, y, skull, fps, replace(params, substeps=substeps), offsets)
                    break
                except SimulationDiverged as diverged:
                    failure = diverged
            else:
                raise SimulationDiverged(f"{failure} even at {substeps} steps per frame: the skull's accelerations or the "
                                         "expression's changes there are beyond what a face's tissue undergoes")
            turned = skull.gravity_change(orient)
            if np.any(turned):
                sag[:, layer.vertices] = layer.gravity_sag(y, turned)
    points = y + offsets
    if noise_cm > 0:
        points += np.random.default_rng(seed).normal(0.0, noise_cm, points.shape).astype(dtype)
    return VolumetricResult(points.astype(dtype, copy=False), offsets, sag, thickness, len(layer.elements), layer.torn,
                            factorizations, iterations)


class Layer:
    """The tetrahedral layer under the skin: nodes, elements, materials and the force model.

    Nodes come in columns, one per skin vertex of the layer (`vertices`), `layers` + 1 deep:
    node = level * V + column, level 0 on the skin, level `layers` on the skull. A node's
    rest position is X(t) = y(t) - (level / layers) * depth * normal(y(t)).

    Given the take's skin `rest_shapes`, elements that some frame's expression would crush
    to under _MIN_QUALITY of their neutral volume (or invert: the built-in face's closed
    mouth line, stretched six-fold by a wide-open jaw) are left out, a tear in the tissue
    there; nodes left in no element are held.
    """

    def __init__(self, neutral: np.ndarray, tri: np.ndarray, weights: np.ndarray, params: VolumetricParams,
                 rest_shapes: np.ndarray | None = None):
        held = weights >= 1.0
        used = tri[~np.all(held[tri], axis=1)]  # triangles with a free vertex
        self.vertices = np.unique(used)
        self.params = params
        columns, levels = len(self.vertices), params.layers
        local = np.searchsorted(self.vertices, used)
        points = neutral[self.vertices]
        self.triangles = local  # the skin's triangles over the layer's columns
        self.outward = _outward_sign(points, local)
        normals = self.normals(points[None])[0]
        w = weights[self.vertices]
        depth = params.thickness_cm * (1.0 - w) + params.bone_thickness_cm * w
        depth *= np.exp(params.thickness_variation * layout.smooth_layout(points, params.layout_seed, layout.DEPTH))
        self.elements, self.depth = _tetrahedralize(points, normals, local, depth, levels, _MIN_DEPTH * params.bone_thickness_cm)
        self.levels = (np.arange(levels + 1) / levels)[:, None, None]  # depth fraction of each level
        node_count = (levels + 1) * columns
        fixed = np.zeros((levels + 1, columns), dtype=bool)
        fixed[levels] = True
        fixed[0] = held[self.vertices]
        self.torn = 0
        if rest_shapes is not None:
            intact = self._intact(neutral, rest_shapes)
            self.elements, self.torn = self.elements[intact], int(np.count_nonzero(~intact))
        fixed.ravel()[_floating_nodes(self.elements, fixed.ravel())] = True
        self.free = np.flatnonzero(~fixed.ravel())
        self.free_columns = self.free % columns  # the skin vertex above each free node
        self.dof = np.full(node_count, -1)
        self.dof[self.free] = np.arange(len(self.free))
        self.skin = np.flatnonzero(~fixed[0])  # free skin nodes (level 0: node = column)

        centroid = points[self.elements % columns].mean(axis=1)
        mu_l = params.shear_modulus * np.exp(params.stiffness_variation * layout.smooth_layout(centroid, params.layout_seed, layout.STIFFNESS))
        lam_l = mu_l * 2 * params.poisson / (1 - 2 * params.poisson)
        self.rho = params.density * np.exp(params.density_variation * layout.smooth_layout(centroid, params.layout_seed, layout.DENSITY))
        self.tau = params.viscosity_time * np.exp(params.damping_variation * layout.smooth_layout(centroid, params.layout_seed, layout.DAMPING))
        self.lame = mu_l, lam_l
        # stable Neo-Hookean's parameters whose rest tangent is linear elasticity with (mu_l, lam_l)
        self.mu = 4.0 / 3.0 * mu_l
        self.lam = lam_l + 5.0 / 6.0 * mu_l
        self.alpha = 1.0 + 0.75 * self.mu / self.lam
        self.stiffening = self.mu * params.nonlinearity

        rest = self.rest_positions(neutral[None, self.vertices])[0]
        self.shape, self.volume = self.geometry(rest)
        mass = np.zeros(node_count)
        np.add.at(mass, self.elements.ravel(), np.repeat(self.rho * self.volume / 4.0, 4))
        self.mass = mass[self.free]
        # nodal gradients of corners 1-3 of each element -> nodes: +1 on the corner, -1 on corner 0
        e = len(self.elements)
        rows = np.concatenate([self.elements[:, 1:].ravel(), np.repeat(self.elements[:, 0], 3)])
        signs = np.repeat([1.0, -1.0], 3 * e)
        self._scatter = sp.csr_matrix((signs, (rows, np.tile(np.arange(3 * e), 2))), shape=(node_count, 3 * e))
        self.damping = self.linear_stiffness(self.shape, self.volume, self.tau)

    def _intact(self, neutral: np.ndarray, rest_shapes: np.ndarray, chunk: int = 64) -> np.ndarray:
        """(E,) elements whose rest volume stays above _MIN_QUALITY of the neutral's in every
        distinct frame of `rest_shapes`."""
        corners = self.rest_positions(neutral[None, self.vertices].astype(np.float64))[0][self.elements]
        neutral_volume = _signed_volumes(corners)
        worst = np.full(len(self.elements), np.inf)
        frames = len(rest_shapes)
        for first in range(0, frames, chunk):
            y = np.asarray(rest_shapes[first:first + chunk, self.vertices], dtype=np.float64)
            changed = np.r_[True, np.any(y[1:] != y[:-1], axis=(1, 2))]
            for frame in y[changed]:
                rest = self.rest_positions(frame[None])[0]
                worst = np.minimum(worst, _signed_volumes(rest[self.elements]) / neutral_volume)
        return worst > _MIN_QUALITY

    def normals(self, y_vertices: np.ndarray) -> np.ndarray:
        """(F, V, 3) outward unit normals of the skin over the layer's columns (area-weighted)."""
        return self.outward * mesh.vertex_normals(y_vertices, self.triangles)

    def rest_positions(self, y_vertices: np.ndarray) -> np.ndarray:
        """(F, nodes, 3) rest configuration X from the skin of the layer's vertices (F, V, 3):
        each column hangs `depth` along the skin's current normal, so it turns with the
        skin (a jaw opening turns the columns under the chin instead of shearing them)."""
        hanging = self.levels[None] * (self.depth[:, None] * self.normals(y_vertices))[:, None]  # (F, L+1, V, 3)
        return (y_vertices[:, None] - hanging).reshape(len(y_vertices), -1, 3)

    def geometry(self, rest: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(inverse edge matrices (E, 3, 3), volumes (E,)) of the elements at rest positions."""
        edges = rest[self.elements[:, 1:]] - rest[self.elements[:, :1]]  # (E, 3 edges, 3)
        matrix = np.swapaxes(edges, 1, 2)  # columns are edges
        return np.linalg.inv(matrix), np.linalg.det(matrix) / 6.0

    def linear_stiffness(self, shape: np.ndarray, volume: np.ndarray, scale: np.ndarray | None = None) -> sp.csc_matrix:
        """Free-free block of the linear elastic stiffness at a rest geometry (times `scale` per element)."""
        mu_l, lam_l = self.lame
        weight = volume if scale is None else volume * scale
        grad = np.concatenate([-shape.sum(axis=1, keepdims=True), shape], axis=1)  # (E, 4, 3) shape-function gradients
        dot = np.einsum("eai,ebi->eab", grad, grad)
        eye = np.eye(3)
        # K[(b, i), (a, j)] = V (mu (G_a . G_b) delta_ij + mu G_a,i G_b,j + lambda G_b,i G_a,j)
        block = (mu_l * weight)[:, None, None, None, None] * (
            dot[:, :, None, :, None] * eye[None, None, :, None, :] + np.einsum("eai,ebj->ebiaj", grad, grad))
        block += (lam_l * weight)[:, None, None, None, None] * np.einsum("ebi,eaj->ebiaj", grad, grad)
        return self._assemble(block.reshape(-1, 12, 12))

    def tangent_stiffness(self, x: np.ndarray, shape: np.ndarray, volume: np.ndarray, eps: float = 1e-7) -> sp.csc_matrix:
        """Free-free block of the elastic tangent at positions x (forward differences of each
        element's gradient, all elements at once, symmetrized, each clamped to positive
        semidefinite): for steps the rest tangent is too far from (large strains, where the
        material stiffens)."""
        corners = x[self.elements]
        base = self._element_gradients(corners, shape, volume)
        block = np.empty((len(corners), 4, 3, 4, 3))
        for a in range(4):
            for j in range(3):
                moved = corners.copy()
                moved[:, a, j] += eps
                block[:, :, :, a, j] = (self._element_gradients(moved, shape, volume) - base) / eps
        block = 0.5 * (block + block.transpose(0, 3, 4, 1, 2)).reshape(-1, 12, 12)
        # projected Newton: each element's tangent clamped to positive semidefinite, so the
        # step's matrix stays definite where compressed elements soften
        values, vectors = np.linalg.eigh(block)
        block = np.matmul(vectors * np.maximum(values, 0.0)[:, None, :], vectors.transpose(0, 2, 1))
        return self._assemble(block)

    def _assemble(self, block: np.ndarray) -> sp.csc_matrix:
        """The free-free block of a matrix from per-element (E, 12, 12) blocks over the elements' dofs."""
        dofs = (3 * self.elements[:, :, None] + np.arange(3)).reshape(-1, 12)
        free_dof = np.full(3 * len(self.dof), -1)
        free_dof[3 * self.free[:, None] + np.arange(3)] = np.arange(3 * len(self.free)).reshape(-1, 3)
        local = free_dof[dofs]
        rows = np.broadcast_to(local[:, :, None], (len(local), 12, 12))
        cols = np.broadcast_to(local[:, None, :], (len(local), 12, 12))
        keep = (rows >= 0) & (cols >= 0)
        size = 3 * len(self.free)
        return sp.csc_matrix((block[keep], (rows[keep], cols[keep])), shape=(size, size))

    def forces(self, x: np.ndarray, shape: np.ndarray, volume: np.ndarray) -> np.ndarray:
        """(nodes, 3) elastic energy gradient at positions x for a rest geometry (shape, volume)."""
        return self._scatter @ self._corner_gradients(x[self.elements[:, 1:]] - x[self.elements[:, :1]], shape, volume).reshape(-1, 3)

    def _element_gradients(self, corners: np.ndarray, shape: np.ndarray, volume: np.ndarray) -> np.ndarray:
        """(E, 4, 3) each element's energy gradient at its corners' positions (E, 4, 3)."""
        nodal = self._corner_gradients(corners[:, 1:] - corners[:, :1], shape, volume)
        return np.concatenate([-nodal.sum(axis=1, keepdims=True), nodal], axis=1)

    def _corner_gradients(self, edges: np.ndarray, shape: np.ndarray, volume: np.ndarray) -> np.ndarray:
        """(E, 3, 3) energy gradient at corners 1-3 (corner 0's is minus their sum) from the edges (E, 3, 3)."""
        f = np.matmul(edges.transpose(0, 2, 1), shape)  # deformation gradients (matmul: einsum is 5x slower here)
        c0, c1, c2 = f[:, :, 0], f[:, :, 1], f[:, :, 2]
        cof = np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=2)
        j = np.sum(c0 * cof[:, :, 0], axis=1)
        ic = np.sum(f * f, axis=(1, 2))
        stretch = ic - 3.0 - 2.0 * (j - 1.0)
        piola = (self.mu * (1.0 - 1.0 / (ic + 1.0)) + self.stiffening * stretch)[:, None, None] * f
        piola += (self.lam * (j - self.alpha) - self.stiffening * stretch)[:, None, None] * cof
        return np.matmul(shape, piola.transpose(0, 2, 1)) * volume[:, None, None]  # V sum_j P_ij shape_kj

    def _sag_shift(self) -> sp.spmatrix:
        """A slight mass shift for the sag's stiffness matrices: keeps them invertible where a
        piece of the layer hangs on by a single node or edge."""
        return sp.diags(np.repeat((2 * np.pi * _SAG_SHIFT_HZ) ** 2 * self.mass, 3))

    def _sag_residual(self, sag, rest, shape, volume, load, x) -> np.ndarray:
        """The sag's static residual on the free nodes: elastic forces at rest + sag minus the load."""
        x[:] = rest
        x[self.free] += sag
        return self.forces(x, shape, volume)[self.free] - load

    @np.errstate(over="ignore", invalid="ignore")  # a trial step running away is a rejected trial
    def _newton_sag(self, sag, rest, shape, volume, load, x) -> np.ndarray | None:
        """The static sag by projected Newton steps with a backtracking line search on the
        residual, from `sag`; None when it does not converge. For frames where chord
        iterations on the rest tangent cycle instead of converging (the layer stiffened far
        from its rest tangent)."""
        residual = self._sag_residual(sag, rest, shape, volume, load, x)
        for _ in range(_NEWTON_ITERATIONS):
            x[:] = rest
            x[self.free] += sag
            step = _factorize_spd(self.tangent_stiffness(x, shape, volume) + self._sag_shift()).solve(residual.reshape(-1)).reshape(-1, 3)
            size = 1.0
            while size > 1e-3:
                trial = self._sag_residual(sag - size * step, rest, shape, volume, load, x)
                if np.linalg.norm(trial) < np.linalg.norm(residual):  # False for a non-finite trial
                    break
                size *= 0.5
            else:
                return None
            sag, residual = sag - size * step, trial
            if np.abs(step).max() <= self.params.tolerance_cm:  # the whole Newton step, not the line search's share
                return sag
        return None

    def gravity_sag(self, y: np.ndarray, turned: np.ndarray) -> np.ndarray:
        """(F, V, 3) static sag of the skin: forces(X + s) = M (g(t) - g(0)) on the free nodes.

        Frame by frame, chord iterations on the rest-tangent stiffness (refactorized as the
        expression's rest shape drifts), started from the previous frames' sag extrapolated;
        where they do not converge, projected Newton steps from the same start.
        """
        frames, columns = len(y), len(self.vertices)
        out = np.zeros((frames, columns, 3))
        sag, previous, solver = np.zeros((len(self.free), 3)), np.zeros((len(self.free), 3)), None
        x = np.empty(((self.params.layers + 1) * columns, 3))
        skin = None
        for f in range(frames):
            if not np.any(turned[f]):
                sag[:], previous[:] = 0.0, 0.0
                continue
            if skin is None or np.any(y[f, self.vertices] != skin):  # held expressions keep their geometry
                skin = y[f, self.vertices]
                rest = self.rest_positions(skin[None].astype(np.float64))[0]
                shape, volume = self.geometry(rest)
            if solver is None or _drift(solver[1], rest, self.elements) > self.params.refactor_strain:
                # the rest tangent only preconditions the iterations
                solver = _factorize_spd(self.linear_stiffness(shape, volume) + self._sag_shift()), rest
            guess = 2.0 * sag - previous
            previous, sag = sag, guess
            load = self.mass[:, None] * turned[f]
            start, converged = sag.copy(), False
            with np.errstate(over="ignore", invalid="ignore"):  # iterations running away end in Newton steps below
                for _ in range(_SAG_ITERATIONS):
                    residual = self._sag_residual(sag, rest, shape, volume, load, x)
                    step = solver[0].solve(residual.reshape(-1)).reshape(-1, 3)
                    sag -= step
                    converged = np.abs(step).max() <= self.params.tolerance_cm
                    if converged or not np.isfinite(step).all():
                        break
            if not converged:  # the rest tangent is too far from where the layer stiffened: Newton steps instead
                sag = self._newton_sag(start, rest, shape, volume, load, x)
                if sag is None:  # not converged: no sag, not a silently wrong truth
                    raise SimulationDiverged(f"the volumetric tissue's gravity sag did not converge at frame {f}: no static "
                                             "equilibrium found for this pose and turn of the head")
            if not np.isfinite(sag).all():  # no sag, not a silent NaN truth
                raise SimulationDiverged(f"the volumetric tissue's gravity sag diverged at frame {f}: no static equilibrium "
                                 "found for this pose and turn of the head")
            out[f, self.skin] = sag[self.dof[self.skin]]
        return out


def _outward_sign(points: np.ndarray, tri: np.ndarray) -> float:
    """+1 if the triangles' winding makes normals point outward, else -1: on a face (convex
    towards the camera) the skin lies on the outward normal's side of its centroid."""
    face = np.cross(points[tri[:, 1]] - points[tri[:, 0]], points[tri[:, 2]] - points[tri[:, 0]])
    centroid = points[tri].mean(axis=1)
    return -1.0 if np.sum((centroid - points.mean(axis=0)) * face) < 0 else 1.0


def _tetrahedralize(points, normals, tri, depth, levels, min_depth):
    """(elements (E, 4) node indices, depth (V,)) of the layer, depth shrunk where prisms fold.

    Each triangle's prism per level splits into three tetrahedra by the lowest-index rule
    (the diagonal of each side quad joins the lower-index vertex's top to the other's
    bottom), so neighbouring prisms share their quads' diagonals and the mesh conforms.
    The depth is first capped by the skin's convex curvature and its slope limited; a
    prism whose tetrahedra are still flatter than _MIN_QUALITY of a right prism as deep as
    its shallowest corner (or inverted) has the depth at its corners shrunk by _SHRINK;
    prisms still folded after _SHRINK_ROUNDS (their corners' normals disagree whatever the
    depth: sharp creases of a real rig's eyelids and lips), or thinner than `min_depth` at
    a corner, are left out of the layer.
    """
    columns = len(points)
    order = np.sort(tri, axis=1)
    # the three tetrahedra of the prism (a0 a1 a2) over (b0 b1 b2): corner indices 0-2 top, 3-5 bottom
    split = np.array([[0, 1, 2, 5], [0, 1, 4, 5], [0, 3, 4, 5]])
    face = np.cross(points[order[:, 1]] - points[order[:, 0]], points[order[:, 2]] - points[order[:, 0]])
    area = 0.5 * np.linalg.norm(face, axis=1)
    outward = np.sign(np.einsum("ti,ti->t", face, normals[order].sum(axis=1)))
    outward[outward == 0] = 1.0
    edges = mesh.unique_edges(order)
    length = np.linalg.norm(points[edges[:, 1]] - points[edges[:, 0]], axis=1)
    depth = np.minimum(depth, _CURVATURE_DEPTH / np.maximum(_convex_curvature(points, normals, edges), 1e-12))
    for _ in range(_SHRINK_ROUNDS):
        depth = _limit_slope(depth, edges, length)
        height = depth[order].min(axis=1) / levels
        top = points[order]
        ideal = np.concatenate([top, top - (outward * height)[:, None, None] * face[:, None] / (2 * area[:, None, None])], axis=1)
        expected = np.sign(_signed_volumes(ideal[:, split]))
        step = (depth[order] / levels)[:, :, None] * normals[order]
        folded = np.zeros(len(order), dtype=bool)
        for level in range(levels):  # the deeper levels fold first where the skin curves tightly
            corners = np.concatenate([top - level * step, top - (level + 1) * step], axis=1)  # (T, 6, 3)
            quality = (_signed_volumes(corners[:, split]) * expected) / (area * height / 3.0)[:, None]
            folded |= np.any(quality < _MIN_QUALITY, axis=1)
        if not folded.any():
            break
        shrink = np.unique(order[folded])
        depth[shrink] *= _SHRINK
    folded |= depth[order].min(axis=1) < min_depth  # too thin to be tissue: a crease the layer skips
    if folded.all():
        raise ValueError("the tissue layer folds under every triangle: the skin mesh is degenerate")
    elements = []
    for level in range(levels):
        nodes = np.concatenate([order + level * columns, order + (level + 1) * columns], axis=1)
        tets = nodes[:, split]  # (T, 3, 4)
        flip = expected < 0
        tets[flip] = tets[flip][:, [1, 0, 2, 3]]
        elements.append(tets[~folded].reshape(-1, 4))
    return np.concatenate(elements), depth


def _limit_slope(depth: np.ndarray, edges: np.ndarray, length: np.ndarray) -> np.ndarray:
    """The largest depth <= `depth` that changes by at most _DEPTH_SLOPE per cm along edges
    (so a locally shrunk depth eases back instead of leaving a step)."""
    depth = depth.copy()
    for _ in range(len(depth)):
        bound = np.minimum(depth[edges[:, 0]], depth[edges[:, 1]]) + _DEPTH_SLOPE * length
        capped = depth.copy()
        np.minimum.at(capped, edges[:, 0], bound)
        np.minimum.at(capped, edges[:, 1], bound)
        if np.array_equal(capped, depth):
            break
        depth = capped
    return depth


def _convex_curvature(points: np.ndarray, normals: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """(V,) largest convex normal curvature over each vertex's edges, (n_j - n_i).(p_j - p_i) / |p_j - p_i|^2:
    an inward offset by depth d folds where d reaches 1 / curvature."""
    delta = points[edges[:, 1]] - points[edges[:, 0]]
    bend = np.einsum("ei,ei->e", normals[edges[:, 1]] - normals[edges[:, 0]], delta) / np.maximum(np.einsum("ei,ei->e", delta, delta), 1e-300)
    curvature = np.zeros(len(points))
    np.maximum.at(curvature, edges[:, 0], bend)
    np.maximum.at(curvature, edges[:, 1], bend)
    return curvature


def _floating_nodes(elements: np.ndarray, fixed: np.ndarray) -> np.ndarray:
    """Nodes in no element, or in a piece of the layer that reaches no fixed node (left
    behind by prisms and elements the layer leaves out): they are held."""
    count = len(fixed)
    pairs = elements[:, [0, 1, 2, 3, 0, 1]], elements[:, [1, 2, 3, 0, 2, 3]]
    graph = sp.coo_matrix((np.ones(pairs[0].size), (pairs[0].ravel(), pairs[1].ravel())), shape=(count, count))
    _, piece = connected_components(graph, directed=False)
    anchored = np.zeros(piece.max() + 1, dtype=bool)
    anchored[piece[fixed]] = True
    used = np.zeros(count, dtype=bool)
    used[elements.ravel()] = True
    return np.flatnonzero(~used | ~anchored[piece])


def _factorize_spd(matrix: sp.spmatrix):
    """SuperLU of a symmetric positive definite matrix: symmetric mode keeps the fill (and
    each solve) about half of the default's."""
    return spla.splu(matrix.tocsc(), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True})


def _signed_volumes(tets: np.ndarray) -> np.ndarray:
    """(..., 4, 3) corner positions -> (...) signed volumes."""
    edges = tets[..., 1:, :] - tets[..., :1, :]
    return np.linalg.det(edges) / 6.0


def _drift(reference: np.ndarray, rest: np.ndarray, elements: np.ndarray) -> float:
    """Largest relative change of an element edge between two rest configurations."""
    def edges(x):
        return x[elements[:, 1:]] - x[elements[:, :1]]

    before, after = edges(reference), edges(rest)
    length = np.linalg.norm(before, axis=2)
    return float(np.max(np.linalg.norm(after - before, axis=2) / length))


class _RestMotion:
    """The layer's skin rest positions y(t), velocities and accelerations at step times,
    from the frames by finite differences (central at a frame, zero acceleration at the
    ends), linear between frames; read frame by frame, so a long take is never copied."""

    def __init__(self, y: np.ndarray, vertices: np.ndarray, fps: float, substeps: int):
        self.y, self.vertices, self.fps, self.substeps = y, vertices, fps, substeps

    def _frame(self, f: int) -> np.ndarray:
        return self.y[min(max(f, 0), len(self.y) - 1), self.vertices].astype(np.float64)

    def _at_frame(self, f: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        before, now, after = self._frame(f - 1), self._frame(f), self._frame(f + 1)
        ends = f == 0 or f == len(self.y) - 1
        velocity = (after - before) * (self.fps if ends else 0.5 * self.fps)
        accel = np.zeros_like(now) if ends else (after - 2.0 * now + before) * self.fps**2
        return now, velocity, accel

    def at(self, step: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(position, velocity, acceleration), each (V, 3), at step `step`."""
        frame, k = divmod(step, self.substeps)
        if k == 0:
            return self._at_frame(frame)
        t = k / self.substeps
        (y0, _, a0), (y1, _, a1) = self._at_frame(frame), self._at_frame(frame + 1)
        return (1 - t) * y0 + t * y1, (y1 - y0) * self.fps, (1 - t) * a0 + t * a1


def _integrate(layer: Layer, y: np.ndarray, skull: SkullMotion, fps: float, params: VolumetricParams, out: np.ndarray):
    """Newmark (average acceleration) from rest; writes the skin's u into out. Returns
    (factorizations, chord iterations).

    Per step, the residual M (a - load(u, v)) + C v + forces(X + u) of the unknown u is
    driven to zero by chord iterations u -= A^-1 residual, A = 4/h^2 M + 2/h C + K_ref,
    with a = 4/h^2 (u - u_n - h v_n) - a_n and v = 2/h (u - u_n) - v_n.
    """
    frames, substeps = len(y), params.substeps
    h = 1.0 / (fps * substeps)
    c1, c2 = 4.0 / (h * h), 2.0 / h
    free, mass, columns = layer.free, layer.mass[:, None], layer.free_columns
    motion = _RestMotion(y, layer.vertices, fps, substeps)
    steps = (frames - 1) * substeps
    linear, omega, alpha = skull.loads(np.arange(steps + 1) / (fps * substeps))

    def load(step, skin_velocity, skin_accel, r, v):
        """Inertial loads per unit mass on the free nodes at positions r, velocities v (skull frame)."""
        w = omega[step]
        return (linear[step] - skin_accel[columns] - np.cross(alpha[step], r)
                - 2.0 * np.cross(w, skin_velocity[columns] + v) - np.cross(w, np.cross(w, r)))

    def factorize(stiffness):
        return _factorize_spd(sp.diags(np.repeat(c1 * layer.mass, 3)) + c2 * layer.damping + stiffness)

    skin, skin_velocity, skin_accel = motion.at(0)
    rest = layer.rest_positions(skin[None])[0]
    shape, volume = layer.geometry(rest)
    u = np.zeros((len(free), 3))
    v = np.zeros_like(u)
    a = load(0, skin_velocity, skin_accel, rest[free], v)
    x = rest.copy()
    solver, reference, factorizations, iterations = factorize(layer.linear_stiffness(shape, volume)), rest, 1, 0
    for step in range(1, steps + 1):
        previous = skin
        skin, skin_velocity, skin_accel = motion.at(step)
        if not np.array_equal(skin, previous):
            rest = layer.rest_positions(skin[None])[0]
            shape, volume = layer.geometry(rest)
            if _drift(reference, rest, layer.elements) > params.refactor_strain:
                solver, reference, factorizations = factorize(layer.linear_stiffness(shape, volume)), rest, factorizations + 1
        u_old, v_old, a_old = u, v, a
        u = u_old + h * v_old + 0.5 * h * h * a_old
        for attempt in range(2):
            for _ in range(_MAX_ITERATIONS):
                iterations += 1
                a = c1 * (u - u_old - h * v_old) - a_old
                v = c2 * (u - u_old) - v_old
                x[:] = rest
                x[free] += u
                residual = mass * (a - load(step, skin_velocity, skin_accel, x[free], v))
                residual += (layer.damping @ v.reshape(-1)).reshape(-1, 3) + layer.forces(x, shape, volume)[free]
                du = solver.solve(residual.reshape(-1)).reshape(-1, 3)
                u = u - du
                if np.abs(du).max() <= params.tolerance_cm or not np.isfinite(du).all():
                    break
            else:
                if attempt == 0:  # refactorize with the tangent where the iterations got to, and try once more
                    x[:] = rest
                    x[free] += u
                    solver, factorizations = factorize(layer.tangent_stiffness(x, shape, volume)), factorizations + 1
                    continue
                raise SimulationDiverged(f"the volumetric tissue did not converge at frame {step // substeps}")
            if not np.isfinite(u).all():
                raise SimulationDiverged(f"the volumetric tissue diverged at frame {step // substeps}")
            break
        a = c1 * (u - u_old - h * v_old) - a_old
        v = c2 * (u - u_old) - v_old
        if step % substeps == 0:
            out[step // substeps][layer.vertices[layer.skin]] = u[layer.dof[layer.skin]]
    return factorizations, iterations
