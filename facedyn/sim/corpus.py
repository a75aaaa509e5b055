"""Simulated takes with known truth, and the papers' capture protocol as a list of them.

A take is a rig driven by expression weights (held, neutral, or real Live Link curves)
while the skull follows a motion (still, walk, run, hop, a vibrating platform, or real
mocap); the soft-tissue simulator adds the secondary dynamics. Every take keeps its truth:
the skull transforms, the quasistatic skin (the rig's shape plus the static gravity sag of
the head's pose, facedyn.sim.tissue) and the offsets (the dynamics: what motion adds).

Protocol (papers/000): per actor, neutral + 10 held expressions, each under stillness,
walking, running, hopping and a platform at 6..11 Hz, about 3 s at 120 fps; a procedural
talking face under every protocol motion (facedyn.sim.speech, no data needed); plus dialog
takes (Live Link curves): speech under real walking and hopping head motion (CMU), and at
the standard scale six other performances (four speech, two range of motion) under every
protocol motion.

For training that learns the physics family rather than one model, `protocol` can give
every take (or the whole corpus) a random actor's tissue, and add procedural dance, turn
and jump takes; test corpora can use the other physics (facedyn.sim.volumetric).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from facedyn.errors import FacedynError, UsageError
from facedyn.geometry import quaternion
from facedyn import motion
from facedyn.rig import FaceRig
from facedyn.sim.speech import speech_weights
from facedyn.sim import tissue as springs, volumetric
from facedyn.sim.tissue import TissueParams
from facedyn.sim.volumetric import VolumetricParams

PLATFORM_HZ = (6, 7, 8, 9, 10, 11)
SPEECH = "MySlate_3_Jason_Millers_iPhone.csv"  # Live Link speech of the dialog test takes
# other Live Link performances, for training: four speech takes, two range-of-motion sessions
PERFORMANCES = ("S07-001.csv", "S88-001.csv", "apfel.csv", "facial.csv", "alex_rom_3.csv", "alex_rom_4.csv")
MOTIONS = ("still", "walk", "run", "hop") + tuple(f"platform:{hz}" for hz in PLATFORM_HZ)
# procedural sources for training only (not tuned to the test takes' mocap): protocol(extra_motions=True)
EXTRA_MOTIONS = ("dance", "turn", "jump")
PHYSICS = {"tissue": TissueParams, "volumetric": VolumetricParams}  # protocol(physics=...) -> its parameters
RANDOMIZE = ("take", "corpus")

# Held expressions as shape-weight recipes, tried in order; a rig gets the first ten whose
# shapes it has (ICT-FaceKit and the built-in face name them eyeBlink_L; ARKit rigs
# eyeBlinkLeft, and one browInnerUp and cheekPuff for both sides: `rig_recipe`).
HELD_EXPRESSIONS: dict[str, dict[str, float]] = {
    "jaw_open": {"jawOpen": 0.8},
    "smile": {"mouthSmile_L": 0.9, "mouthSmile_R": 0.9},
    "pucker": {"mouthPucker": 0.9},
    "brow_raise": {"browInnerUp_L": 0.8, "browInnerUp_R": 0.8, "browOuterUp_L": 0.6, "browOuterUp_R": 0.6},
    "cheek_puff": {"cheekPuff_L": 0.9, "cheekPuff_R": 0.9},
    "blink": {"eyeBlink_L": 1.0, "eyeBlink_R": 1.0},
    "funnel": {"mouthFunnel": 0.9, "jawOpen": 0.3},
    "frown": {"mouthFrown_L": 0.9, "mouthFrown_R": 0.9, "browDown_L": 0.6, "browDown_R": 0.6},
    "smile_left": {"mouthSmile_L": 1.0, "eyeSquint_L": 0.5},
    "smile_right": {"mouthSmile_R": 1.0, "eyeSquint_R": 0.5},
    "jaw_wide": {"jawOpen": 0.5, "mouthStretch_L": 0.7, "mouthStretch_R": 0.7},
    "sneer": {"noseSneer_L": 0.8, "noseSneer_R": 0.8, "mouthUpperUp_L": 0.5, "mouthUpperUp_R": 0.5},
    "half_open": {"jawOpen": 0.4},
    "wink_left": {"eyeBlink_L": 1.0},
}


@dataclass(frozen=True)
class TakeSpec:
    """What to simulate: an expression source under a skull motion."""

    name: str
    motion: str  # still | walk | run | hop | dance | turn | jump | platform:HZ[:side|up|forward] | bvh:PATH[#JOINT]
    expression: str | None = None  # a HELD_EXPRESSIONS key, None = neutral
    dialog: str | None = None  # a Live Link Face CSV driving the expression instead
    speech: bool = False  # a procedural talking face drawn from `seed` instead (facedyn.sim.speech)
    duration_s: float = 3.0
    fps: float = 120.0
    seed: int = 0
    noise_cm: float = 0.0
    platform_amplitude_cm: float = motion.PLATFORM_AMPLITUDE_CM
    impacts: bool = False  # gaits jolt at each foot contact (facedyn.motion._contact_transients)
    # the take's own physics and actor (TissueParams or VolumetricParams); None: the corpus's
    tissue: TissueParams | VolumetricParams | None = None


@dataclass
class SimulatedPerformance:
    """A take and its truth, all arrays; skull space is the rig's space."""

    spec: TakeSpec
    frames: np.ndarray  # (F,) time codes, 1-based
    fps: float
    skull_translate: np.ndarray  # (F, 3) true skull transform
    skull_orient: np.ndarray  # (F, 4) w, x, y, z
    captured: np.ndarray  # (F, N, 3) skull space: quasistatic + offsets (+ tracking noise)
    quasistatic: np.ndarray  # (F, N, 3) true quasistatic skin, skull space: the rig's shape + gravity sag
    offsets: np.ndarray  # (F, N, 3) true secondary dynamics, skull space
    weights: np.ndarray  # (F, K) the expression weights that drove the rig
    info: dict = field(default_factory=dict)

    def world_points(self) -> np.ndarray:
        rot = quaternion.to_matrix(self.skull_orient)
        return (np.einsum("fij,fnj->fni", rot, self.captured.astype(np.float64)) + self.skull_translate[:, None]).astype(np.float32)


def skull_motion(spec: TakeSpec) -> motion.SkullTrajectory:
    """The spec's skull trajectory, `duration_s` long at `fps`."""
    kind, _, arg = spec.motion.partition(":")
    common = dict(duration_s=spec.duration_s, fps=spec.fps, seed=spec.seed)
    if kind == "still":
        return motion.still(**common)
    if kind in ("walk", "run", "hop") + EXTRA_MOTIONS:
        return getattr(motion, kind)(**common, impacts=spec.impacts)
    if kind == "platform":
        try:
            hz, axis = motion.parse_platform(arg)
        except ValueError as error:
            raise ValueError(f"take {spec.name}: {error}") from None
        return motion.platform(hz, spec.platform_amplitude_cm, **common, axis=axis)
    if kind == "bvh":
        path, _, joint = arg.partition("#")
        return motion.from_bvh(path, joint or "Head", duration_s=spec.duration_s, fps=spec.fps, seed=spec.seed)
    raise ValueError(f"take {spec.name}: unknown motion {spec.motion!r}; use still, walk, run, hop, dance, turn, jump, platform:HZ or bvh:PATH")


def expression_weights(rig: FaceRig, spec: TakeSpec, frame_count: int) -> np.ndarray:
    """(F, K) weights: neutral, a held expression eased in over 0.3 s, dialog curves or procedural speech."""
    if spec.speech:
        if spec.dialog is not None or spec.expression is not None:
            raise ValueError(f"take {spec.name}: a procedural speech take has no held expression or dialog curves of its own")
        return speech_weights(rig.expression_names, frame_count, spec.fps, spec.seed)
    weights = np.zeros((frame_count, rig.expression_count), np.float32)
    if spec.dialog is not None:
        from facedyn.io.livelink import read_livelink_csv
        from facedyn.io.resample import resample_curves

        curves = resample_curves(read_livelink_csv(spec.dialog, rig.expression_names), spec.fps)
        available = len(curves.weights)
        start = int(np.random.default_rng(spec.seed).integers(0, max(available - frame_count, 0) + 1))
        rows = np.minimum(np.arange(start, start + frame_count), available - 1)  # hold the last pose if short
        columns = [rig.shape_index(name) for name in curves.names]
        weights[:, columns] = limit_rate(curves.weights[rows], spec.fps)
        return weights
    if spec.expression is not None:
        recipe = rig_recipe(rig.expression_names, HELD_EXPRESSIONS[spec.expression]) or {}
        ease = np.clip(np.arange(frame_count) / (0.3 * spec.fps), 0.0, 1.0)
        ease = ease * ease * (3 - 2 * ease)
        for shape, value in recipe.items():
            weights[:, rig.shape_index(shape)] = value * ease
    return weights


# The fastest a face moves, in expression weight per second. A blink, the fastest facial
# action, closes the lid in about 75-100 ms, its fastest part at about twice its mean speed;
# speech moves lips and jaw slower. So no weight of a face crosses its 0..1 range much
# faster than in 1/30 s: a Live Link curve that does is a tracking jump (a lost frame, a
# re-acquired face), not a face. The shared Live Link takes peak at 27/s (blinks at 60 fps),
# 13-16/s at 30 fps, so real performances pass unchanged.
MAX_WEIGHT_RATE = 30.0


def limit_rate(weights: np.ndarray, fps: float, rate: float = MAX_WEIGHT_RATE) -> np.ndarray:
    """(F, K) weights whose frame-to-frame change is at most `rate` / fps (a slew limiter:
    a jump becomes a ramp at the bound, anything slower is kept exactly)."""
    out = np.array(weights, dtype=np.float32)
    step = np.float32(rate / fps)
    change = np.diff(out, axis=0)
    if np.all(np.abs(change) <= step):
        return out
    for f in range(1, len(out)):
        out[f] = out[f - 1] + np.clip(weights[f] - out[f - 1], -step, step)
    return out


def simulate_take(rig: FaceRig, spec: TakeSpec, tissue: TissueParams | VolumetricParams | None = None) -> SimulatedPerformance:
    """Simulate one take with its own physics (spec.tissue), else `tissue`, else the default
    TissueParams; the parameters' type picks the physics (facedyn.sim.tissue or .volumetric)."""
    trajectory = skull_motion(spec)
    frame_count = trajectory.frame_count
    weights = expression_weights(rig, spec, frame_count)
    quasistatic = rig.evaluate(weights) if rig.expression_count else np.repeat(rig.neutral[None], frame_count, 0)
    params = spec.tissue or tissue or TissueParams()
    physics = volumetric if isinstance(params, VolumetricParams) else springs
    try:
        result = physics.simulate(
            quasistatic, rig.topology.triangles(), trajectory.translate, trajectory.orient, spec.fps, params,
            noise_cm=spec.noise_cm, seed=spec.seed, rigid_weights=rig.rigid_weights, neutral=rig.neutral,
        )
    except springs.SimulationDiverged as exc:
        raise springs.SimulationDiverged(f"take {spec.name}: {exc}") from None
    return SimulatedPerformance(
        spec=spec,
        frames=np.arange(1, frame_count + 1, dtype=np.float64),
        fps=spec.fps,
        skull_translate=trajectory.translate,
        skull_orient=trajectory.orient,
        captured=result.points.astype(np.float32),
        quasistatic=(quasistatic + result.gravity_sag).astype(np.float32),
        offsets=result.dynamics.astype(np.float32),
        weights=weights,
        info={"motion": spec.motion, "expression": spec.expression, "dialog": spec.dialog and Path(spec.dialog).name, "speech": spec.speech,
              "physics": physics.__name__.rsplit(".", 1)[-1], "substeps": getattr(result, "substeps", params.substeps)},
    )


_worker_setup: tuple = ()


def _init_worker(rig: FaceRig, tissue: TissueParams | VolumetricParams | None) -> None:
    global _worker_setup
    _worker_setup = (rig, tissue)


def _simulate_in_worker(spec: TakeSpec) -> SimulatedPerformance:
    rig, tissue = _worker_setup
    return simulate_take(rig, spec, tissue)


def _simulate_caught(rig: FaceRig, spec: TakeSpec, tissue) -> tuple[TakeSpec, SimulatedPerformance | None, str | None]:
    """(spec, take, None), or (spec, None, the error) when the take's input or physics fails (a FacedynError)."""
    try:
        return spec, simulate_take(rig, spec, tissue), None
    except FacedynError as exc:
        return spec, None, str(exc).removeprefix(f"take {spec.name}: ")


def _simulate_caught_in_worker(spec: TakeSpec):
    rig, tissue = _worker_setup
    return _simulate_caught(rig, spec, tissue)


def simulate_each(rig: FaceRig, specs: list[TakeSpec], tissue: TissueParams | VolumetricParams | None = None, jobs: int = 1):
    """(spec, take, error) for every spec, as each finishes (`jobs` at a time in worker processes):
    a take that fails (a FacedynError: it diverged, its data cannot be read) comes back as
    its error, and the others go on. Interrupted, no queued take is started."""
    if jobs <= 1 or len(specs) <= 1:
        for spec in specs:
            yield _simulate_caught(rig, spec, tissue)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    context = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(max_workers=min(jobs, len(specs)), mp_context=context, initializer=_init_worker, initargs=(rig, tissue))
    try:
        for future in as_completed([pool.submit(_simulate_caught_in_worker, spec) for spec in specs]):
            yield future.result()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def simulate_takes(rig: FaceRig, specs: list[TakeSpec], tissue: TissueParams | VolumetricParams | None = None, jobs: int = 1):
    """Simulated takes in the order of `specs`, `jobs` at a time in worker processes.

    One simulation is a sequential time loop on one core (single-threaded BLAS), so a
    corpus uses every core by simulating several takes at once.
    """
    if jobs <= 1 or len(specs) <= 1:
        for spec in specs:
            yield simulate_take(rig, spec, tissue)
        return
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    context = multiprocessing.get_context("spawn")  # no fork of a process holding threads
    with ProcessPoolExecutor(max_workers=jobs, mp_context=context, initializer=_init_worker, initargs=(rig, tissue)) as pool:
        yield from pool.map(_simulate_in_worker, specs)


def held_expressions(rig: FaceRig, count: int = 10) -> list[str]:
    """The first `count` HELD_EXPRESSIONS whose shapes the rig has (all of them, by any of their names)."""
    return [key for key, recipe in HELD_EXPRESSIONS.items() if rig_recipe(rig.expression_names, recipe) is not None][:count]


def rig_recipe(names, recipe: dict[str, float]) -> dict[str, float] | None:
    """A recipe in the rig's shape names: mouthSmile_L as mouthSmile_L or mouthSmileLeft (ARKit), a
    side of a shape the rig does not split (ARKit's browInnerUp, cheekPuff) as that shape; None
    when the rig lacks one."""
    names = set(names)
    weights: dict[str, float] = {}
    for shape, value in recipe.items():
        candidates = [shape]
        if shape.endswith(("_L", "_R")):
            candidates += [shape[:-2] + ("Left" if shape.endswith("_L") else "Right"), shape[:-2]]
        found = next((name for name in candidates if name in names), None)
        if found is None:
            return None
        weights[found] = max(weights.get(found, 0.0), value)
    return weights


def protocol(
    rig: FaceRig,
    scale: str = "standard",
    data_dir: Path | None = None,
    seed: int = 0,
    noise_cm: float = 0.0,
    *,
    physics: str = "tissue",
    randomize_tissue: str | None = None,
    extra_motions: bool = False,
    impacts: bool = False,
    soft_hz: tuple[float, float] | None = None,
) -> list[TakeSpec]:
    """The capture protocol at a scale: 'standard' (the paper's) or 'demo' (a quick subset).

    Dialog takes need the Live Link curves and CMU mocap in `data_dir` (../shared/data; a
    folder without them is an error, `check_data_folder`); without a data folder there are
    none (the procedural speech takes stay).
    `physics` ('tissue' or 'volumetric') and `randomize_tissue` set each take's physics:
    None keeps the corpus's (TissueParams() unless the caller passes one; 'volumetric'
    gives every take VolumetricParams()), 'corpus' draws one random actor from `seed`,
    'take' one per take from the take's seed, so a corpus is the same whatever the number
    of workers. `extra_motions` adds the held expressions under EXTRA_MOTIONS (dance,
    turn, jump), training sources not tuned to the test takes' mocap; `impacts` makes every
    gait jolt at its foot contacts, as real walking and hopping do (facedyn.motion).
    `soft_hz` (low, high) narrows the randomized tissue's soft frequency band (the family's
    otherwise), e.g. to an actor's band measured on a calibration session.
    """
    if physics not in PHYSICS:
        raise ValueError(f"physics must be one of {', '.join(PHYSICS)}, got {physics!r}")
    if randomize_tissue not in (None,) + RANDOMIZE:
        raise ValueError(f"randomize_tissue must be None, 'take' or 'corpus', got {randomize_tissue!r}")
    check_data_folder(data_dir, scale, "data_dir")
    specs = _protocol_takes(rig, scale, data_dir, seed, noise_cm, extra_motions)
    if impacts:
        specs = [replace(spec, impacts=True) for spec in specs]
    if soft_hz is not None and randomize_tissue is None:
        raise ValueError("a soft_hz band draws randomized tissue: it needs randomize_tissue 'take' or 'corpus'")
    params = PHYSICS[physics]
    band = {} if soft_hz is None else {"soft_hz": soft_hz}
    if randomize_tissue == "take":
        return [replace(spec, tissue=params.random(spec.seed, **band)) for spec in specs]
    if randomize_tissue == "corpus":
        actor = params.random(seed, **band)
        return [replace(spec, tissue=actor) for spec in specs]
    if physics != "tissue":
        return [replace(spec, tissue=params()) for spec in specs]
    return specs


def _protocol_takes(rig: FaceRig, scale: str, data_dir: Path | None, seed: int, noise_cm: float, extra_motions: bool) -> list[TakeSpec]:
    """The protocol's takes, before any physics is chosen."""
    if scale == "standard":
        expressions, motions, duration, dialog_s = held_expressions(rig, 10), MOTIONS, 3.0, 6.0
    elif scale == "demo":
        expressions, motions, duration, dialog_s = held_expressions(rig, 3), ("still", "walk", "hop", "platform:7", "platform:9", "platform:11"), 2.0, 3.0
    else:
        raise ValueError(f"scale must be 'demo' or 'standard', got {scale!r}")
    specs = []
    take_seed = seed
    for expression in [None] + expressions:
        for kind in motions + (EXTRA_MOTIONS if extra_motions and expression else ()):
            take_seed += 1
            label = expression or "neutral"
            specs.append(TakeSpec(f"{label}_{motion_label(kind)}", kind, expression, duration_s=duration, seed=take_seed, noise_cm=noise_cm))
            if expression is None and scale == "standard":
                break  # the neutral is captured once, standing still
    specs += speech_takes(motions, duration, seed + 3000, noise_cm)
    specs += dialog_takes(data_dir, dialog_s, seed + 1000, noise_cm)
    if scale == "standard":
        specs += performance_takes(data_dir, motions, duration, seed + 2000, noise_cm)
    return specs


def motion_label(kind: str) -> str:
    """A protocol motion as it reads in take names: walk, platform9hz."""
    return kind.replace(":", "") + ("hz" if kind.startswith("platform") else "")


def speech_takes(motions, duration_s: float, seed: int, noise_cm: float) -> list[TakeSpec]:
    """A procedural talking face (facedyn.sim.speech) under every protocol motion: performances
    without downloaded data, so F and H see expressions change while the head moves.

    Named dialog_* like the Live Link performances: the paper's F must not train on them.
    """
    return [TakeSpec(f"dialog_speech_{motion_label(kind)}", kind, speech=True, duration_s=duration_s, seed=seed + i, noise_cm=noise_cm)
            for i, kind in enumerate(motions)]


DIALOG_MOCAP = {"walk": "131_01.bvh", "hop": "131_03.bvh"}  # CMU subject 131, the dialog takes' head motion


def data_files(scale: str) -> list[str]:
    """The files, relative to a --data folder, that the protocol at `scale` reads."""
    files = [f"livelink-face/{SPEECH}"] + [f"cmu-mocap/{name}" for name in DIALOG_MOCAP.values()]
    return files + ([f"livelink-face/{csv}" for csv in PERFORMANCES] if scale == "standard" else [])


def takes_matching(specs: list[TakeSpec], pattern: str, scale: str, flag: str = "--only") -> list[TakeSpec]:
    """The protocol's takes whose name matches the glob `pattern` (all when it is empty); a
    UsageError when none does, so a mistyped pattern never plans an empty corpus."""
    import fnmatch

    if not pattern:
        return specs
    matching = [s for s in specs if fnmatch.fnmatch(s.name, pattern)]
    if not matching:
        raise UsageError(f"{flag}: no take of the {scale} protocol matches {pattern!r}")
    return matching


def check_data_folder(data_dir: Path | None, scale: str, flag: str = "--data") -> None:
    """A UsageError unless `data_dir` (when given) is a folder holding every file the protocol
    reads from it: a mistyped folder must not quietly give a corpus without its dialog takes."""
    if data_dir is None:
        return
    data_dir = Path(data_dir)
    expected = "livelink-face/ (Live Link Face CSVs) and cmu-mocap/ (CMU BVH files), as ../shared/data"
    if not data_dir.is_dir():
        raise UsageError(f"{flag} {data_dir}: {'not a folder' if data_dir.exists() else 'no such folder'}; expected a folder "
                         f"holding {expected}")
    missing = [name for name in data_files(scale) if not (data_dir / name).is_file()]
    if missing:
        raise UsageError(f"{flag} {data_dir}: missing {', '.join(missing)}; the {scale} protocol's dialog takes read them "
                         f"(a folder holding {expected})")


def dialog_takes(data_dir: Path | None, duration_s: float, seed: int, noise_cm: float) -> list[TakeSpec]:
    """Speech under real walking and hopping head motion, from the shared data (none without a data folder)."""
    if data_dir is None:
        return []
    data_dir = Path(data_dir)
    csv = data_dir / "livelink-face" / SPEECH
    mocap = data_dir / "cmu-mocap"
    return [
        TakeSpec(f"dialog_{name}", f"bvh:{mocap / bvh}", dialog=str(csv), duration_s=duration_s, seed=seed + i, noise_cm=noise_cm)
        for i, (name, bvh) in enumerate(DIALOG_MOCAP.items())
    ]


def performance_takes(data_dir: Path | None, motions, duration_s: float, seed: int, noise_cm: float) -> list[TakeSpec]:
    """Other Live Link performances under every protocol motion (the paper captures dialog
    under the same motions as the held expressions), when the shared data is there.

    Named dialog_* like the speech takes: the paper's F must not train on them (a
    performance has no moving-average target), F on true dynamics and H should.
    """
    if data_dir is None:
        return []
    data_dir = Path(data_dir)
    specs = []
    for csv in PERFORMANCES:
        for kind in motions:
            specs.append(TakeSpec(f"dialog_{Path(csv).stem.replace('-', '_')}_{motion_label(kind)}", kind, dialog=str(data_dir / "livelink-face" / csv), duration_s=duration_s,
                                  seed=seed + len(specs), noise_cm=noise_cm))
    return specs
