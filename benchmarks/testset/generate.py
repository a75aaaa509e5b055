"""Generate a test-set actor: MuJoCo tissue takes as plain USD captures with their truth beside.

An actor folder holds:
  actor.json                 the actor (face, identity, tissue, shell), its takes and what they cost
  rig.usda                   the actor's rig (UsdSkel blend shapes): what a studio has of its actor
  takes/<take>/tracked.usdc  the plain capture: a time-sampled Mesh of world-space points with
                             tracker noise, metres, Z up, 60 fps, frames from 1001, no facedyn schema
  takes/<take>/truth.npz     the truth, per captured frame, in the rig's (skull) space, cm, Y up

Truth (all per captured frame; vertices outside the face region move rigidly with the skull
and the rig, their dynamics are 0):
  skull_translate (F,3) cm, skull_orient (F,4) wxyz: the skull trajectory that drove the bone
  captured (F,N,3): the noise-free simulated skin in skull space (R^T (world - T))
  quasistatic (F,N,3): the skin of the take's still twin: the same MuJoCo tissue and the
      same expression drive with the skull held still, gravity turned into the skull frame
      as the take's pose turns it (so the sag of each pose is quasistatic, not dynamics)
  dynamics (F,N,3) = captured - quasistatic: what the skull's motion adds. The expression's
      own inertia (lips overshooting a fast viseme) is in both runs, so it is part of the
      performance here, not of the dynamics (facedyn's own simulators count it as dynamics)
  face_vertices: the vertices the figures are taken over (those with tissue under them)
  weights (F,K): the expression weights that drove the bone
Both runs start 0.5 s before the first captured frame (LEAD_S) from frame 0's static
equilibrium, the expression eased in from the neutral over the first 0.3 s of that lead.
"""
from __future__ import annotations

import json
import os
import platform
import shutil
import tempfile
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from facedyn.geometry import quaternion
from facedyn.sim.noise import TrackerNoise, add_tracker_noise
from facedyn.rig import FaceRig
from testset.actors import FPS, SUBSTEPS, ActorSpec, cross_actor_takes, session_takes, test_takes, transfer_takes
from testset.takes import LEAD_S, TakeRecipe, expression_weights, skull_trajectory
from testset.tissue import Drive, MujocoTissue, TissueParams

TRACKER = TrackerNoise(iid_cm=0.01, temporal_cm=0.004, spatial_cm=0.002, pop_rate=1.0, pop_cm=0.3, drop_rate=0.01)


class Drives:
    """The kinematic drive of each MuJoCo step, computed when asked (a take's would not fit in memory on ICT)."""

    def __init__(self, tissue: MujocoTissue, rig: FaceRig, translate_cm: np.ndarray, orient: np.ndarray, weights: np.ndarray):
        self.rotation = quaternion.to_matrix(orient)
        self.translation = translate_cm / 100.0
        self.weights = weights
        basis = expression_basis(rig)[:, tissue.driven_skin]  # (K, D, 3) cm
        self.basis = basis.reshape(len(basis), -1) / 100.0
        self.rest = tissue.shell.nodes[tissue.driven_nodes]

    def __len__(self) -> int:
        return len(self.weights)

    def __getitem__(self, n: int) -> Drive:
        targets = self.rest + (self.weights[n] @ self.basis).reshape(-1, 3)
        return Drive(self.rotation[n], self.translation[n], targets)


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3 - 2 * x)


def expression_basis(rig: FaceRig) -> np.ndarray:
    """(K, N, 3) cm: each expression shape's displacement at full weight."""
    if rig.expression_count == 0:
        return np.zeros((0, rig.point_count, 3), np.float32)
    return rig.evaluate(np.eye(rig.expression_count, dtype=np.float32)) - rig.neutral[None]


def simulate_take(rig: FaceRig, tissue: MujocoTissue, recipe: TakeRecipe, data: Path, fps: float = FPS) -> dict:
    """One take's capture (world cm) and truth arrays, the lead-in cut off; the tissue's step rate is a multiple of `fps`."""
    substeps = int(round(1.0 / (fps * tissue.model.opt.timestep)))
    rate = fps * substeps
    trajectory = skull_trajectory(recipe, data, rate)
    steps = len(trajectory.translate)
    weights = expression_weights(recipe, rig.expression_names, data, rate, steps)
    weights *= _smoothstep(np.arange(steps) / (LEAD_S * 0.6 * rate))[:, None]  # from the neutral's equilibrium, in the lead-in
    drives = Drives(tissue, rig, trajectory.translate, trajectory.orient, weights)
    skin_world = tissue.simulate(drives, substeps) * 100.0  # (frames, S, 3) cm
    kept = np.arange(int(round(LEAD_S * fps)), len(skin_world))
    recorded = kept * substeps
    rotation, translate = drives.rotation[recorded], trajectory.translate[recorded]
    posed = rig.evaluate(weights[recorded].astype(np.float32)).astype(np.float64)  # (F, N, 3) the rig, skull space
    captured = posed.copy()
    skin = tissue.shell.skin
    captured[:, skin] = np.einsum("fji,fnj->fni", rotation, skin_world[kept] - translate[:, None])
    quasistatic = posed.copy()
    quasistatic[:, skin] = tissue.simulate(drives, substeps, still=True)[kept] * 100.0
    world = np.einsum("fij,fnj->fni", rotation, captured) + translate[:, None]
    return {"frames": 1001 + np.arange(len(kept)), "fps": fps, "skull_translate": translate, "skull_orient": trajectory.orient[recorded],
            "world": world, "captured": captured, "quasistatic": quasistatic, "dynamics": captured - quasistatic,
            "weights": weights[recorded], "face_vertices": np.asarray(skin)}


def write_take(folder: Path, take: dict, rig: FaceRig, seed: int) -> None:
    """tracked.usdc (the capture with tracker noise) and truth.npz into `folder`."""
    from plain_capture import write_plain_cache

    folder.mkdir(parents=True)
    tracked = add_tracker_noise(take["world"].astype(np.float32), take["fps"], TRACKER, rig.neutral, seed=seed)
    write_plain_cache(folder / "tracked.usdc", tracked.points, rig.topology.face_vertex_counts, rig.topology.face_vertex_indices, take["fps"])
    np.savez_compressed(folder / "truth.npz", **{k: np.asarray(v, np.float32 if k in ("captured", "quasistatic", "dynamics", "weights") else None)
                                                 for k, v in take.items() if k != "world"})


def actor_rig(spec: ActorSpec, data: Path) -> FaceRig:
    """The actor's face: the base rig with an identity drawn from `identity_seed`."""
    if spec.face == "default":
        from facedyn.sim.default_face import default_face

        base = default_face()
    elif spec.face == "ict":
        from facedyn.usd.blendshape_rig import read_blendshape_rig

        base = read_blendshape_rig(data / "ict-facekit" / "ict_face_rig.usdc")
    else:
        raise ValueError(f"actor {spec.name}: unknown face {spec.face!r} (default or ict)")
    if spec.identity_seed is None:
        return base
    return base.make_actor(seed=spec.identity_seed, name=spec.name)


def generate_actor(spec: ActorSpec, out: Path, data: Path, which: tuple[str, ...] = ("session", "test"), seconds_scale: float = 1.0,
                   jobs: int = 1, progress=print, source: ActorSpec | None = None) -> Path:
    """Write the actor folder `out` (atomically: a temporary folder renamed into place); `jobs`
    takes at a time in worker processes (each simulation is one sequential loop on one core).
    "cross" in `which` needs `source`, the actor whose run the cross take moves like."""
    from facedyn.usd.blendshape_rig import write_blendshape_rig

    if out.exists():
        raise FileExistsError(f"{out}: already exists (remove it to generate the actor again)")
    started = time.perf_counter()
    recipes = []
    if "session" in which:
        recipes += session_takes(spec.take_seed, 2.0 * seconds_scale)
    if "test" in which:
        recipes += test_takes(spec.take_seed, 2.5 * seconds_scale)
    if "transfer" in which:
        recipes += transfer_takes(spec.take_seed, 2.5 * seconds_scale)
    if "cross" in which:
        if source is None or source.face != spec.face or source.name == spec.name:
            raise ValueError(f"cross takes need another actor of the {spec.face} face as their source, got {source and source.name}")
        recipes += cross_actor_takes(spec.take_seed, source, 2.5 * seconds_scale)
    out.parent.mkdir(parents=True, exist_ok=True)
    scratch = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        _init_worker(spec, data)
        rig, tissue = _worker
        write_blendshape_rig(rig, scratch / "rig.usda")
        takes = []
        for recipe, take, seconds in _simulated(spec, data, recipes, jobs):
            write_take(scratch / "takes" / recipe.name, take, rig, seed=recipe.seed)
            rms = float(np.sqrt(np.mean(np.sum(take["dynamics"][:, take["face_vertices"]] ** 2, axis=-1))))
            takes.append({**asdict(recipe), "frames": len(take["frames"]), "dynamics_rms_mm": round(rms * 10, 3), "seconds": seconds})
            progress(f"{spec.name} {recipe.name}: {len(take['frames'])} frames, dynamics {rms * 10:.3f} mm RMS, {seconds} s")
        shell = tissue.shell
        info = {"actor": asdict(spec), "simulator": f"MuJoCo {tissue.mujoco.__version__} flex (dim 3), testset.tissue",
                "tissue": asdict(tissue.params), "shell": {"nodes": len(shell.nodes), "tetrahedra": len(shell.tets), "skin_vertices": len(shell.skin),
                                                           "pinned_columns": int(shell.pinned.sum()), "muscle_columns": int((~shell.pinned).sum())},
                "fps": FPS, "substeps": SUBSTEPS[spec.face], "lead_in_s": LEAD_S, "rig": {"name": rig.name, "points": rig.point_count},
                "takes": takes, "seconds": round(time.perf_counter() - started, 1), "jobs": jobs, "machine": platform.node(), "cpus": os.cpu_count()}
        (scratch / "actor.json").write_text(json.dumps(info, indent=1) + "\n")
        scratch.rename(out)
    except BaseException:
        shutil.rmtree(scratch, ignore_errors=True)
        raise
    return out


_worker: tuple = ()


def _init_worker(spec: ActorSpec, data: Path) -> None:
    """The actor's rig and MuJoCo tissue, built once per process."""
    global _worker
    rig = actor_rig(spec, data)
    _worker = (rig, MujocoTissue(rig.neutral, rig.topology.triangles(), rig.face_vertices, TissueParams.random(spec.tissue_seed),
                                 1.0 / (FPS * SUBSTEPS[spec.face])))


def _simulate_in_worker(recipe: TakeRecipe, data: Path) -> tuple[TakeRecipe, dict, float]:
    rig, tissue = _worker
    t0 = time.perf_counter()
    take = simulate_take(rig, tissue, recipe, data)
    return recipe, take, round(time.perf_counter() - t0, 1)


def _simulated(spec: ActorSpec, data: Path, recipes: list[TakeRecipe], jobs: int):
    """(recipe, take, seconds) in the order of `recipes`."""
    if jobs <= 1 or len(recipes) <= 1:
        for recipe in recipes:
            yield _simulate_in_worker(recipe, data)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=jobs, mp_context=context, initializer=_init_worker, initargs=(spec, data)) as pool:
        yield from pool.map(_simulate_in_worker, recipes, [data] * len(recipes))
