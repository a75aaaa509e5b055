"""Soft tissue that facedyn did not write: MuJoCo's flex elasticity over the actor's own bone.

The layer (testset.shell) is one MuJoCo `flexcomp type="direct" dim="3"`: every node a body
with three world-aligned slide joints, MuJoCo's 3-D flex elasticity (Young's modulus,
Poisson ratio), gravity on, explicit Euler steps in the WORLD frame: the skull moves, the
tissue's inertia is MuJoCo's own, nothing is transformed into the skull frame. Node masses
are each node's share of its tetrahedra (floored at 0.7 x the median: mass scaling, the
lightest nodes set the explicit step's limit).

Driving (all kinematic, as a mocap body would be but with the bone's true velocity, which
MuJoCo's mocap bodies lack; the nodes' qpos/qvel are overwritten before every step):
- pinned inner nodes (where the layer reaches the bone) follow the skull and the
  expression: skull(t) o (rest + the expression's displacement of the skin above): the
  deep layer slides with the muscles, the skin follows through the tissue;
- skin nodes on the rim of the face region (where the tissue goes on into the scalp and
  neck, which are rigid here) follow skull(t) o rig(t);
- unpinned inner nodes (over deep fat and cavities) are pulled toward their target by soft
  "muscle" springs: the column above rings at `muscle_hz` on it, with damping;
- rig vertices outside the face region (eyes, teeth, scalp) follow skull o rig(t) rigidly.
Damping: MuJoCo's flex damping is unstable with explicit steps at this stiffness and its
'discrete' integrator is 20x slower, so the tissue's damping is a viscous force on each free
node relative to the bone's velocity field at it (mass proportional: c = 2 damping_ratio
2 pi soft_hz), applied through qfrc_applied.

The quasistatic twin (`simulate(..., still=True)`): the same model, the same expression
drive, the skull held at the origin, gravity turned into the skull frame as each step's pose
turns it. Both runs start from the static equilibrium of frame 0 (`_solve`: chord iterations
on MuJoCo's passive and gravity forces with a stiffness taken from them by finite
differences), the skin moving with the bone.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from testset.shell import Shell, build_shell

GRAVITY = np.array([0.0, -9.81, 0.0])  # m/s^2, Y up (facedyn's world axes)
_FD_STEP = 1e-6  # m: finite-difference step of the stiffness
_TOLERANCE = 1e-6  # m: an equilibrium's largest correction at convergence (1 micron; dynamics are millimetres)
_CHORD_ITERATIONS = 25  # per stiffness
_RETAKES = 4  # stiffness retakes before an equilibrium is given up
_MASS_FLOOR = 0.7  # of the median node mass


@dataclass(frozen=True)
class TissueParams:
    """One test actor's tissue (SI units); `random(seed)` draws one."""

    young_pa: float = 600.0
    poisson: float = 0.4  # compressible enough for explicit steps of 1.2 ms (the bulk wave sets the step)
    density: float = 1050.0
    damping_ratio: float = 0.15  # of the mass-proportional damping at soft_hz
    soft_hz: float = 7.0  # sets the damping coefficient only (the stiffness sets the frequencies)
    muscle_hz: float = 6.0
    muscle_damping_ratio: float = 0.3
    max_depth_cm: float = 1.0
    min_bone_depth_cm: float = 0.4
    bulge_gain: float = 3.0
    pin_gap_cm: float = 0.1
    layers: int = 1
    depth_variation: float = 0.15  # std of the log of the smooth random factor on the bone depth
    layout_seed: int = 0

    @classmethod
    def random(cls, seed: int) -> "TissueParams":
        rng = np.random.default_rng(seed)
        return cls(young_pa=float(np.exp(rng.uniform(np.log(550.0), np.log(1100.0)))), poisson=float(rng.uniform(0.38, 0.42)),
                   damping_ratio=float(rng.uniform(0.08, 0.25)), soft_hz=float(rng.uniform(5.0, 9.0)),
                   muscle_hz=float(rng.uniform(5.0, 8.0)), muscle_damping_ratio=float(rng.uniform(0.2, 0.5)),
                   max_depth_cm=float(rng.uniform(0.8, 1.2)), min_bone_depth_cm=float(rng.uniform(0.3, 0.5)),
                   bulge_gain=float(rng.uniform(2.5, 3.5)), layout_seed=int(rng.integers(1 << 30)))

    def depth_field(self, points_cm: np.ndarray) -> np.ndarray:
        """A smooth random factor over the face (a few random plane waves 5-15 cm long)."""
        rng = np.random.default_rng(self.layout_seed)
        waves = rng.standard_normal((6, 3))
        waves *= (2 * np.pi / rng.uniform(5.0, 15.0, 6) / np.linalg.norm(waves, axis=1))[:, None]
        field_ = np.sin(points_cm @ waves.T + rng.uniform(0, 2 * np.pi, 6)).sum(axis=1) / np.sqrt(3.0)
        return np.exp(self.depth_variation * field_)


@dataclass
class Drive:
    """The kinematic inputs at one instant, skull space (m): the skull, the driven nodes' targets."""

    rotation: np.ndarray  # (3, 3)
    translation: np.ndarray  # (3,) m
    targets: np.ndarray  # (D, 3) kinematic and muscle nodes' targets, skull space, m


class MujocoTissue:
    """A rig's face over MuJoCo tissue: build once per actor, then `simulate` its takes (and their still twins)."""

    def __init__(self, neutral_cm: np.ndarray, triangles: np.ndarray, face_vertices: np.ndarray, params: TissueParams, timestep: float):
        import mujoco

        self.mujoco = mujoco
        self.params = params
        self.shell: Shell = build_shell(neutral_cm, triangles, face_vertices, max_depth_cm=params.max_depth_cm,
                                        min_bone_depth_cm=params.min_bone_depth_cm, bulge_gain=params.bulge_gain,
                                        layers=params.layers, pin_gap_cm=params.pin_gap_cm,
                                        depth_field=params.depth_field(np.asarray(neutral_cm, np.float64)))
        shell = self.shell
        self.model = _compile(mujoco, _xml(shell, params, timestep))
        self.data = mujoco.MjData(self.model)
        bodies = self.model.flex_vertbodyid[: len(shell.nodes)]
        mass = shell.masses * params.density
        mass = np.maximum(mass, _MASS_FLOOR * np.median(mass))  # mass scaling: the explicit step's stability is set by the lightest nodes
        self.model.body_mass[bodies] = mass  # flexcomp spreads `mass` evenly: each node gets its own tetrahedra's share instead
        mujoco.mj_setConst(self.model, self.data)  # ... which the mass matrix only sees once the constants are recomputed
        self.dof = self.model.body_dofadr[bodies][:, None] + np.arange(3)  # (V, 3) dof of node v, axis k
        self.origin = self.model.body_pos[bodies].copy()  # slide joints: a node's position is its body's origin + qpos
        self.kinematic = np.concatenate([shell.inner[shell.pinned], np.flatnonzero(shell.rim)])
        self.muscle = shell.inner[~shell.pinned]
        driven = np.zeros(len(shell.nodes), bool)
        driven[self.kinematic] = True
        self.free = np.flatnonzero(~driven)
        self.mass = mass
        column_mass = np.bincount(np.arange(len(shell.nodes)) % len(shell.skin), mass)[self.muscle % len(shell.skin)]
        self.muscle_k = column_mass * (2 * np.pi * params.muscle_hz) ** 2  # the column above rings at muscle_hz on it
        self.muscle_c = 2 * params.muscle_damping_ratio * column_mass * 2 * np.pi * params.muscle_hz
        self.damping = 2 * params.damping_ratio * 2 * np.pi * params.soft_hz  # 1/s, times the node's mass
        # a driven node's target = its rest position + the expression displacement of the skin vertex above it
        column = np.arange(len(shell.nodes)) % len(shell.skin)
        self.driven_nodes = np.concatenate([self.kinematic, self.muscle])
        self.driven_skin = shell.skin[column[self.driven_nodes]]
        self._stiffness = None
        self._upright_state = None

    # -- the dynamic simulation, world frame ------------------------------------------------
    def simulate(self, drives, record_every: int, still: bool = False) -> np.ndarray:
        """Step through `drives` (one per MuJoCo step); the skin nodes' positions (m) every
        `record_every` steps, from the first; starts at frame 0's equilibrium, moving with the bone.

        still: the same expression with the skull held at the origin and gravity turned into
        the skull frame as each step's pose turns it (skull-space positions): the quasistatic twin.
        """
        mujoco, m, d = self.mujoco, self.model, self.data
        if still:
            drives = _Still(drives)
        m.opt.gravity[:] = drives.gravity(0) if still else GRAVITY
        dt = m.opt.timestep
        start = self._solve(self._upright(), (drives.drives if still else drives).rotation[0].T @ GRAVITY, drives[0])
        m.opt.gravity[:] = drives.gravity(0) if still else GRAVITY
        x = _to_world(drives[0], start)
        v = (_to_world(drives[1], start) - x) / dt
        d.qpos[self.dof] = x - self.origin
        d.qvel[self.dof] = v
        nk, skin = len(self.kinematic), len(self.shell.skin)
        free_dof, kin_dof, mus_dof = self.dof[self.free], self.dof[self.kinematic], self.dof[self.muscle]
        out = []
        last = len(drives) - 1
        for n in range(len(drives)):
            here, after, before = drives[n], drives[min(n + 1, last)], drives[max(n - 1, 0)]
            span = dt * (min(n + 1, last) - max(n - 1, 0))  # central differences, one-sided at the ends
            target_now = _to_world(here, here.targets)
            target_velocity = (_to_world(after, after.targets) - _to_world(before, before.targets)) / span
            if still:
                m.opt.gravity[:] = drives.gravity(n)
            d.qpos[kin_dof] = target_now[:nk] - self.origin[self.kinematic]
            d.qvel[kin_dof] = target_velocity[:nk]
            if n % record_every == 0:
                out.append(d.qpos[self.dof[:skin]] + self.origin[:skin])
            x, v = d.qpos[free_dof] + self.origin[self.free], d.qvel[free_dof]
            bone_velocity = _bone_velocity(before, after, x, span)
            d.qfrc_applied[:] = 0.0
            d.qfrc_applied[free_dof] = -self.damping * self.mass[self.free, None] * (v - bone_velocity)
            xm, vm = d.qpos[mus_dof] + self.origin[self.muscle], d.qvel[mus_dof]
            d.qfrc_applied[mus_dof] += -self.muscle_k[:, None] * (xm - target_now[nk:]) - self.muscle_c[:, None] * (vm - target_velocity[nk:])
            mujoco.mj_step(m, d)
            if not np.isfinite(d.qpos).all() or np.abs(d.qvel).max() > 50.0:
                raise FloatingPointError(f"the MuJoCo tissue diverged at step {n} (|v| > 50 m/s)")
        return np.asarray(out)

    # -- static equilibria, skull frame ------------------------------------------------------
    def _solve(self, x: np.ndarray, gravity: np.ndarray, drive: Drive) -> np.ndarray:
        """Chord iterations with backtracking (a step that raises the residual is halved); where
        they stall (the expression took the tissue far from where the stiffness was taken),
        the stiffness is retaken at the current state and they go on."""
        nk = len(self.kinematic)
        x = x.copy()
        x[self.kinematic] = drive.targets[:nk]
        residual = self._residual(x, gravity, drive.targets[nk:])
        for retake in range(_RETAKES + 1):
            if retake:
                self._stiffness = spla.factorized(self._finite_difference_stiffness(x, drive).tocsc())
            solve = self._factorized()
            for _ in range(_CHORD_ITERATIONS):
                step = solve(residual).reshape(-1, 3)
                for _ in range(8):
                    trial = x.copy()
                    trial[self.free] += step
                    trial_residual = self._residual(trial, gravity, drive.targets[nk:])
                    if np.linalg.norm(trial_residual) <= np.linalg.norm(residual) or np.abs(step).max() < _TOLERANCE:
                        break
                    step = 0.5 * step
                x, residual = trial, trial_residual
                if np.abs(step).max() < _TOLERANCE:
                    return x
        raise FloatingPointError(f"the quasistatic equilibrium did not converge ({_RETAKES} stiffness retakes of {_CHORD_ITERATIONS} "
                                 f"chord iterations; last correction {np.abs(step).max() * 1e6:.2f} micron)")

    def _upright(self) -> np.ndarray:
        """The neutral face's equilibrium under upright gravity (skull space, m), reached in load steps; the chord
        stiffness is last taken there (the sagged state every frame starts near)."""
        if self._upright_state is None:
            rest = Drive(np.eye(3), np.zeros(3), self.shell.nodes[self.driven_nodes])
            x = self.shell.nodes.copy()
            for load in (0.25, 0.5, 0.75, 1.0, 1.0):  # Newton over load steps: the stiffness retaken at each
                self._stiffness = spla.factorized(self._finite_difference_stiffness(x, rest).tocsc())
                x = self._solve(x, load * GRAVITY, rest)
            self._upright_state = x
        return self._upright_state

    def _residual(self, x: np.ndarray, gravity: np.ndarray, muscle_targets: np.ndarray) -> np.ndarray:
        """Net force (N) on the free nodes at rest in configuration x: MuJoCo's passive (elastic)
        and gravity forces, and the muscle springs."""
        m, d = self.model, self.data
        m.opt.gravity[:] = gravity
        d.qpos[self.dof] = x - self.origin
        d.qvel[:] = 0.0
        d.qfrc_applied[:] = 0.0
        self.mujoco.mj_forward(m, d)
        force = d.qfrc_passive[self.dof] - d.qfrc_bias[self.dof]
        force[self.muscle] += -self.muscle_k[:, None] * (x[self.muscle] - muscle_targets)
        return force[self.free].ravel()

    def _factorized(self):
        """K^-1 (K = -d force / d x over the free nodes, MuJoCo's forces by finite differences
        over a distance-2 colouring of the nodes), factorized when (re)taken."""
        if self._stiffness is None:
            rest = Drive(np.eye(3), np.zeros(3), self.shell.nodes[self.driven_nodes])
            self._stiffness = spla.factorized(self._finite_difference_stiffness(self.shell.nodes, rest).tocsc())
        return self._stiffness

    def _finite_difference_stiffness(self, state: np.ndarray, drive: Drive) -> sp.csr_matrix:
        """K at `state`: one force evaluation per colour and axis (nodes of a colour share no tetrahedron's neighbour)."""
        shell = self.shell
        n = len(shell.nodes)
        rest = state
        muscle_targets = drive.targets[len(self.kinematic):]
        zero = np.zeros(3)
        tets = shell.tets
        pairs = np.stack(np.meshgrid(np.arange(4), np.arange(4)), -1).reshape(-1, 2)
        rows, cols = tets[:, pairs[:, 0]].ravel(), tets[:, pairs[:, 1]].ravel()
        adjacency = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n)).tocsr()
        adjacency.data[:] = 1.0
        local = np.full(n, -1)
        local[self.free] = np.arange(len(self.free))
        colours = _distance2_colouring(adjacency, self.free)
        base = self._residual(rest, zero, muscle_targets).reshape(-1, 3)
        entries_r, entries_c, entries_v = [], [], []
        for colour in range(colours.max() + 1):
            nodes = self.free[colours == colour]
            neighbours = adjacency[nodes]  # rows: the perturbed nodes; columns: the nodes they touch
            for axis in range(3):
                x = rest.copy()
                x[nodes, axis] += _FD_STEP
                change = (self._residual(x, zero, muscle_targets).reshape(-1, 3) - base) / _FD_STEP
                coo = neighbours.tocoo()
                keep = local[coo.col] >= 0
                source, target = nodes[coo.row[keep]], coo.col[keep]
                values = -change[local[target]]  # (P, 3) rows: target node's 3 forces
                for k in range(3):
                    entries_r.append(3 * local[target] + k)
                    entries_c.append(3 * local[source] + axis)
                    entries_v.append(values[:, k])
        size = 3 * len(self.free)
        stiffness = sp.coo_matrix((np.concatenate(entries_v), (np.concatenate(entries_r), np.concatenate(entries_c))), shape=(size, size)).tocsr()
        return 0.5 * (stiffness + stiffness.T)


class _Still:
    """A take's drives with the skull held still; its pose only turns gravity (skull frame)."""

    def __init__(self, drives):
        self.drives = drives

    def __len__(self) -> int:
        return len(self.drives)

    def __getitem__(self, n: int) -> Drive:
        return Drive(np.eye(3), np.zeros(3), self.drives[n].targets)

    def gravity(self, n: int) -> np.ndarray:
        return self.drives.rotation[n].T @ GRAVITY


def _distance2_colouring(adjacency: sp.csr_matrix, nodes: np.ndarray) -> np.ndarray:
    """Greedy colours of `nodes` such that two nodes of one colour share no neighbour (nor touch)."""
    two_hop = (adjacency @ adjacency).tocsr()
    colour = np.full(adjacency.shape[0], -1)
    for v in nodes:
        near = two_hop.indices[two_hop.indptr[v]:two_hop.indptr[v + 1]]
        used = set(colour[near][colour[near] >= 0].tolist())
        c = 0
        while c in used:
            c += 1
        colour[v] = c
    return colour[nodes]


def _to_world(drive: Drive, points: np.ndarray) -> np.ndarray:
    return points @ drive.rotation.T + drive.translation


def _bone_velocity(before: Drive, after: Drive, x: np.ndarray, span: float) -> np.ndarray:
    """The bone's rigid velocity field at world points x (central difference of the skull)."""
    local = (x - before.translation) @ before.rotation  # x in the earlier skull frame
    return (_to_world(after, local) - x) / span


# MuJoCo's compiler does not count 3-D flex elasticity as a passive force in this check (the
# tests see the layer sag and ring down); anything else it says is passed on.
_BENIGN = "is not rigid and has no equality constraints or passive forces"


def _compile(mujoco, xml: str):
    """The model, MuJoCo's warnings raised as Python warnings (not appended to MUJOCO_LOG.TXT in the working folder)."""
    import warnings

    said = []
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(said.append)
    try:
        model = mujoco.MjModel.from_xml_string(xml)
    finally:
        mujoco.set_mju_user_warning(previous)
    for text in said:
        if _BENIGN not in text:
            warnings.warn(f"MuJoCo: {text}", RuntimeWarning, stacklevel=3)
    return model


def _xml(shell: Shell, params: TissueParams, timestep: float) -> str:
    points = " ".join(f"{v:.8g}" for v in shell.nodes.ravel())
    elements = " ".join(map(str, shell.tets.ravel()))
    return f"""<mujoco model="facedyn-testset-tissue">
  <option timestep="{timestep:.9g}" gravity="0 -9.81 0" integrator="Euler">
    <flag contact="disable" constraint="disable"/>
  </option>
  <worldbody>
    <flexcomp name="tissue" type="direct" dim="3" point="{points}" element="{elements}" mass="1" radius="0.0005">
      <contact contype="0" conaffinity="0" selfcollide="none"/>
      <elasticity young="{params.young_pa:.9g}" poisson="{params.poisson:.9g}" damping="0"/>
    </flexcomp>
  </worldbody>
</mujoco>"""
