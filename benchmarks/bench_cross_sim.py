"""The cross-simulator protocol (issue 18): train on facedyn's simulator, test on another physics.

Training, all through the console as a studio runs it (the built-in face, written as a
UsdSkel rig so that `simulate --rig` and `actor --from rig` read the same file):
  usdfacedyn simulate --rig rig.usda --scale demo --randomize-tissue take --extra-motions --impacts --noise 0.01 --data DATA
  usdfacedyn actor rig.usda                          (the actor frame: the rig's own space)
  usdfacedyn train-removal   (three F variants, equal budgets: --epochs/--subsample below)
      F_truth_acc: true dynamics, landmark accelerations over t-30..t+10, sample positions,
                   batches of 2,000 (the recommended F, as the demo trains it)
      F_truth_vel: the same with the paper's landmark velocities over t-10..t+10
      F_paper:     the paper's moving-average targets and velocities, batches of 10,000
  usdfacedyn train-synthesis --quasistatic F_truth_acc (H through the recommended F)
The corpus's Live Link dialog takes (CMU 131_01 walking, 131_03 hopping: the test takes'
speech) are left out of all training (--exclude dialog_walk,dialog_hop); the procedural
talking takes (dialog_speech_*, facedyn.sim.speech) train F on true dynamics and H, not the
paper's F (a performance has no moving-average target: --exclude 'dialog*'). Every take
has random spring-membrane tissue (TissueParams).

Testing: ``--actors`` actors with volumetric hyperelastic tissue (facedyn.sim.volumetric,
another family) drawn by VolumetricParams.random from seeds training never used; each
actor's takes carry tracker noise (correlated in time and over the surface, pops, dropped
frames: facedyn.sim.noise), are exported as plain mesh caches (metres, Z up, frame 1001,
no truth, no rest) and go through `import`, `stabilize --actor actor.usda`, `remove`,
`synthesize` with the defaults. Test takes (Live Link speech, never in training):
  - dialog under real walking (CMU 131_02) and a procedural run (training has no run);
  - a held smile on a 8 Hz platform (training has 7, 9 and 11 Hz);
  - synthesis under new motion: the dialog under CMU 131_03 hopping; H synthesizes the
    dynamics from F's quasistatic output and the solved skull; against the true dynamics.
    The linear response's expression term reads that quasistatic skin, which holds what F
    left of the take's own dynamics; from the true quasistatic shapes (and the true skull)
    it cannot read them back: ``linear_response_true_skull_true_quasistatic_upper_bound``.
Calibration (the paper trains H per actor, on the actor's captures through F): each test
actor also gives a calibration session, nine held expressions of 4.5 s (--session-seconds: a
40 s session) under motions no test take uses (platforms at 6, 7, 9, 10 and 11 Hz, a procedural walk, jump, dance and head
turns, their gaits jolting at foot contacts as training's do; no run, no hop, no 8 Hz), captured and stabilized as above, and
  usdfacedyn train-synthesis CALIBRATION_TAKES --calibrate H.synthesis --quasistatic F_truth_acc.removal
goes on training the family's H on them (100 epochs; no truth: F's output is y(t)), and
  usdfacedyn train-synthesis CALIBRATION_TAKES --calibrate H.synthesis --response linear
fits the actor's linear response to the skull on them (no F, no truth: each take holds one
expression; facedyn.dynamics.response). Synthesis reports H_calibrated and linear_response
beside the family's H; removal reports linear_response (`remove --model` with it) and
mean_of_family_F_and_linear_response (`remove --model F --blend RESPONSE`) beside the F's,
and removal_chosen_on_session_motion_left: the candidate (each F, the response, the mean)
that leaves the least of the session's motion beyond its held shapes and sag (`evaluate
--session --removal M [--blend N]`, the response's own takes each removed by the response
fitted without them; no truth).
Tissue band (`--soft-hz-bands`, default 5-6.5 and 7.5-9 Hz): the recommended F is trained
once more per band, each on its own corpus (`simulate ... --soft-hz BAND`: the same protocol and
seeds, the tissue's soft frequency drawn from the band; the same budget), and each test actor
keeps the candidate (the family's F or a band's) that leaves its held expressions most alike
across motions on its calibration session (`evaluate --held-expression --removal F` on the
session's two pairs of takes that hold one expression: smile on the 6 Hz platform and
dancing, jaw open on the 10 Hz platform and turning; no truth). Removal cases report every
candidate (``F_truth_acc_<candidate>_solved``: the family's equals ``F_truth_acc_solved``)
and the chosen one (``F_truth_acc_chosen_on_session_solved``).
Retargeting (A -> B, both volumetric test actors of a group, one topology): A's dialog
under CMU hopping, captured and processed as above (A's take with its quasistatic layer),
retargeted onto B's dialog under walking (B's quasistatic layer) with `usdfacedyn retarget`
(B's synthesis model: the family's H, B's calibrated H and B's linear response; and `--method delta-transfer`,
A's removed offsets copied), scored against B's true dynamics under A's true skull motion
(B's tissue simulating B's expression under A's motion). Target: synthesis <= 0.5x delta
transfer. A test take whose volumetric simulation diverges is reported as such and its
cases are left out.

Held-out actors (``--held-out-actors K``): volumetric actors from seeds (HELD_OUT_SEEDS)
that were never simulated while the training family was tuned; their JSON carries
``"held_out": true``. Run them only for final figures.

Every figure is RMS over the face vertices as a fraction of the true dynamics' RMS
("do nothing" = 100%): ``solved`` = the real path (solved skull, actor frame); ``true_skull``
= F (or H) given the simulator's true skull and the tracked points in true skull space: an
upper bound, no capture has it; ``moving_average`` = the 21-frame moving average baseline
on the solved take. One JSON object per case.

    .venv/bin/python benchmarks/bench_cross_sim.py [--actors 2] [--held-out-actors 0] [--epochs 8] [--subsample 0.5] [--h-epochs 20] [--seconds 1.5] [--session-seconds 4.5] [--work DIR] [--out FILE] [--note TEXT]

A small-budget protocol (demo-scale corpus with the procedural talking takes, no Live Link
performances, short takes, few epochs). Measured on 2 cores: `simulate` 106 s (under a load of
3-5), the four models 3.3 minutes, each test actor 5-11 minutes with its calibration.
"""
from __future__ import annotations

import json
import os
import tempfile
import time
from pathlib import Path

import numpy as np

from facedyn.dynamics.modelfile import load_model
from facedyn.dynamics.removal import remove_dynamics
from facedyn.dynamics.response import remove_with_response
from facedyn.dynamics.synthesis import synthesize_dynamics
from facedyn.dynamics.targets import dynamic_offsets
from facedyn.evaluation import residual_fraction
from facedyn.geometry import quaternion
from facedyn.motion import PLATFORM_AMPLITUDE_CM
from facedyn.sim.corpus import SPEECH, TakeSpec, simulate_take, simulate_takes
from facedyn.sim.default_face import default_face
from facedyn.sim import volumetric
from facedyn.sim.noise import TrackerNoise, add_tracker_noise
from facedyn.sim.volumetric import VolumetricParams
from facedyn.sim.tissue import SimulationDiverged
from harness import Recorder, parser
from plain_capture import stabilize_with_cli, usdfacedyn, write_plain_cache

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
TRACKER = TrackerNoise(iid_cm=0.01, temporal_cm=0.004, spatial_cm=0.002, pop_rate=1.0, pop_cm=0.3, drop_rate=0.01)
ACTOR_SEEDS = (1801, 1802, 1803, 1804)  # VolumetricParams.random seeds: no training take draws volumetric tissue
HELD_OUT_SEEDS = (1901, 1902, 1903, 1904)  # never simulated while the training family was tuned (final figures only)
SOFT_HZ_BANDS = ("5-6.5", "7.5-9")  # simulate --soft-hz: the family's low and high ends, beside the whole 5-9 Hz
TEST_SPEECH_TAKES = "dialog_walk,dialog_hop"  # the corpus's Live Link takes of the test takes' speech
RECOMMENDED_INPUTS = ("--sample-positions", "true", "--batch-size", "2000", "--exclude", TEST_SPEECH_TAKES)
F_VARIANTS = {  # name: (train-removal --target, --skull-features, its other flags)
    "F_truth_acc": ("truth", "acceleration", RECOMMENDED_INPUTS),
    "F_truth_vel": ("truth", "velocity", RECOMMENDED_INPUTS),
    "F_paper": ("moving-average", "velocity", ("--exclude", "dialog*")),
}
RECOMMENDED = "F_truth_acc"
BLEND = "mean_of_family_F_and_linear_response"  # remove --model F --blend RESPONSE
SESSION_SECONDS = 4.5  # per held expression of the calibration session
CALIBRATION = (  # (take, motion, held expression) of each test actor's calibration session
    ("cal_smile_platform6hz", "platform:6", "smile"), ("cal_brow_platform7hz", "platform:7", "brow_raise"),
    ("cal_puff_platform9hz", "platform:9", "cheek_puff"), ("cal_jaw_platform10hz", "platform:10", "jaw_open"),
    ("cal_funnel_platform11hz", "platform:11", "funnel"), ("cal_pucker_walk", "walk", "pucker"),
    ("cal_frown_jump", "jump", "frown"), ("cal_smile_dance", "dance", "smile"), ("cal_jaw_turn", "turn", "jaw_open"),
)


HORIZONTAL = {  # --horizontal-platforms: two of the session's platforms shaken horizontally instead (take, motion, amplitude cm)
    "cal_smile_platform6hz": ("cal_smile_side4hz", "platform:4:side", 1.0),  # 0.64 g
    "cal_jaw_platform10hz": ("cal_jaw_forward7hz", "platform:7:forward", 0.4),  # 0.79 g
}


def test_specs(seconds: float, seed: int) -> dict[str, TakeSpec]:
    speech = str(DATA / "livelink-face" / SPEECH)
    return {
        "dialog_walk": TakeSpec("dialog_cmu_131_02", f"bvh:{DATA / 'cmu-mocap' / '131_02.bvh'}", dialog=speech, duration_s=seconds, seed=seed + 1),
        "dialog_run": TakeSpec("dialog_run", "run", dialog=speech, duration_s=seconds, seed=seed + 2),
        "platform_8hz": TakeSpec("smile_platform8hz", "platform:8", "smile", duration_s=seconds, seed=seed + 3),
        "dialog_hop": TakeSpec("dialog_cmu_131_03", f"bvh:{DATA / 'cmu-mocap' / '131_03.bvh'}", dialog=speech, duration_s=seconds, seed=seed + 4),
    }


def train(work: Path, rig_path: Path, args) -> dict:
    """The corpus, the actor and the models, through the console; seconds per step."""
    seconds = {}

    def step(name, *command):
        t0 = time.perf_counter()
        usdfacedyn(*command)
        seconds[name] = round(time.perf_counter() - t0, 1)

    step("simulate", "simulate", "-o", str(work / "corpus"), *corpus_flags(rig_path, args))
    step("actor", "actor", str(rig_path), "-o", str(work / "actor.usda"))
    for name, (target, features, flags) in F_VARIANTS.items():
        step(name, "train-removal", str(work / "corpus"), "-o", str(work / f"{name}.removal"), "--target", target,
             "--skull-features", features, *flags, *f_budget(args))
    step("H", "train-synthesis", str(work / "corpus"), "-o", str(work / "H.synthesis"), "--quasistatic", str(work / f"{RECOMMENDED}.removal"),
         "--epochs", str(args.h_epochs), "--skull", "truth", "--exclude", TEST_SPEECH_TAKES, "--device", "cpu")
    return seconds


def corpus_flags(rig_path: Path, args) -> tuple[str, ...]:
    return ("--rig", str(rig_path), "--scale", "demo", "--randomize-tissue", "take", "--extra-motions", "true", "--impacts", "true",
            "--noise", "0.01", "--data", str(DATA), "--jobs", str(args.jobs))


def f_budget(args) -> tuple[str, ...]:
    return ("--epochs", str(args.epochs), "--subsample", str(args.subsample), "--skull", "truth", "--device", "cpu")


def band_model(work: Path, band: str) -> Path:
    return work / f"{RECOMMENDED}_soft{band}.removal"


def band_paths(work: Path, args) -> dict[str, Path]:
    """The candidate recommended F's by name: the family's and one per --soft-hz band."""
    return {"family": work / f"{RECOMMENDED}.removal", **{f"soft{b}": band_model(work, b) for b in args.soft_hz_bands}}


def train_bands(work: Path, rig_path: Path, args) -> dict:
    """The recommended F once more per --soft-hz band (its own corpus: the same protocol and
    seeds, tissue drawn from the band; the same budget); models already in `work` are kept."""
    seconds = {}
    for band in args.soft_hz_bands:
        if band_model(work, band).is_file():
            continue
        t0 = time.perf_counter()
        usdfacedyn("simulate", "-o", str(work / f"corpus_soft{band}"), *corpus_flags(rig_path, args), "--soft-hz", band)
        target, features, flags = F_VARIANTS[RECOMMENDED]
        usdfacedyn("train-removal", str(work / f"corpus_soft{band}"), "-o", str(band_model(work, band)), "--target", target,
                   "--skull-features", features, *flags, *f_budget(args))
        seconds[band] = round(time.perf_counter() - t0, 1)
    return seconds


def choose_removal(roots: dict[str, Path], session: dict[str, TakeSpec], candidates: dict[str, Path], folder: Path) -> tuple[str, dict]:
    """The candidate F that leaves the actor's held expressions most alike across motions, no
    truth: `usdfacedyn evaluate --held-expression --removal F` on each pair of calibration
    takes holding one expression; (its name, every candidate's mean spread ratio)."""
    pairs = [[root for label, root in roots.items() if session[label].expression == shared] for shared in ("smile", "jaw_open")]
    pairs = [pair for pair in pairs if len(pair) == 2]
    ratios = {}
    for name, model in candidates.items():
        ratio = []
        for k, pair in enumerate(pairs):
            out = folder / f"evaluate_{name}_{k}"
            usdfacedyn("evaluate", *map(str, pair), "--held-expression", "true", "--removal", str(model), "-o", str(out))
            ratio.append(json.loads((out / "report.json").read_text())["held_expression"]["per_frame_ratio"])
        ratios[name] = round(float(np.mean(ratio)), 4) if ratio else None
    scored = {name: r for name, r in ratios.items() if r is not None}
    return (min(scored, key=scored.get) if scored else "family"), ratios


def choose_on_session(roots: dict[str, Path], candidates: dict[str, Path], response: Path, folder: Path) -> tuple[str, dict]:
    """The removal (a candidate F, the actor's linear response, or the mean of the family F's
    and the response's) that leaves the least of the session's motion beyond its held
    shapes and sag, no truth: `usdfacedyn evaluate --session --removal M [--blend N]` on the
    session's takes (the response's own takes each removed by the response fitted without
    them); (its name, every candidate's fraction)."""
    runs = {name: ("--removal", str(model)) for name, model in candidates.items()}
    runs["linear_response"] = ("--removal", str(response))
    runs[BLEND] = ("--removal", str(candidates["family"]), "--blend", str(response))
    left = {}
    for name, flags in runs.items():
        out = folder / f"session_{name}"
        usdfacedyn("evaluate", *map(str, roots.values()), "--session", "true", *flags, "-o", str(out))
        left[name] = json.loads((out / "report.json").read_text())["session"]["motion_left_beyond_sag"]
    return min(left, key=left.get), left


def plain_capture(sim, rig, folder: Path, actor: Path):
    """A take's tracked points (tracker noise) as a plain cache, imported and stabilized with
    the actor through the console; (take root, tracked points)."""
    tracked = add_tracker_noise(sim.world_points(), sim.fps, TRACKER, rig.neutral, seed=sim.spec.seed)
    folder.mkdir(parents=True)
    write_plain_cache(folder / "tracked.usdc", tracked.points, rig.topology.face_vertex_counts, rig.topology.face_vertex_indices, sim.fps)
    stabilize_with_cli(folder / "tracked.usdc", folder, actor)
    return folder / "take.usda", tracked


class TestTake:
    """A volumetric take's truth, its plain capture through the console, and the layers read back."""

    def __init__(self, sim, rig, folder: Path, actor: Path, models: Path, response: Path):
        from facedyn.usd.take import read_layers, read_take

        self.truth = sim
        self.root, tracked = plain_capture(sim, rig, folder, actor)
        rot = quaternion.to_matrix(sim.skull_orient)
        # the tracked points in the true skull's space (for the upper bound)
        self.tracked_true_skull = np.einsum("fji,fnj->fni", rot, tracked.points - sim.skull_translate[:, None]).astype(np.float32)
        root = self.root
        self.stabilized, _ = read_take(root)
        self.removed = {}
        for name in F_VARIANTS:
            layer = folder / f"quasistatic.{name}.usdc"
            usdfacedyn("remove", str(root), "-o", str(layer), "--model", str(models / f"{name}.removal"))
            self.removed[name] = read_layers([layer, root])
        layer = folder / "quasistatic.usdc"
        usdfacedyn("remove", str(root), "-o", str(layer), "--attach", str(root), "--model", str(models / f"{RECOMMENDED}.removal"))
        layer = folder / "quasistatic.linear_response.usdc"
        usdfacedyn("remove", str(root), "-o", str(layer), "--model", str(response))
        self.removed_by_response = read_layers([layer, root])
        layer = folder / f"quasistatic.{BLEND}.usdc"
        usdfacedyn("remove", str(root), "-o", str(layer), "--model", str(models / f"{RECOMMENDED}.removal"), "--blend", str(response))
        self.removed_by_blend = read_layers([layer, root])
        self.synthesized = {"H": self.synthesize(models / "H.synthesis", "synthesized.usdc")}

    def synthesize(self, model: Path, name: str):
        """The take's dynamics synthesized by `model` (a layer beside the take, not attached)."""
        from facedyn.usd.take import read_layers

        layer = self.root.parent / name
        usdfacedyn("synthesize", str(self.root), "-o", str(layer), "--model", str(model))
        return read_layers([layer, self.root])


def calibration_specs(seconds: float, seed: int, horizontal: bool = False) -> dict[str, TakeSpec]:
    """An actor's calibration session: held expressions under motions none of the test takes
    use (platforms but not 8 Hz, a procedural walk, jump, dance and turn; no run, no hop);
    horizontal: two platforms shaken sideways and fore and aft instead (HORIZONTAL)."""
    specs = {}
    for k, (name, motion, expression) in enumerate(CALIBRATION):
        amplitude = PLATFORM_AMPLITUDE_CM
        if horizontal and name in HORIZONTAL:
            name, motion, amplitude = HORIZONTAL[name]
        specs[name] = TakeSpec(name, motion, expression, duration_s=seconds, seed=seed + 100 + k, impacts=True, platform_amplitude_cm=amplitude)
    return specs


def session_models(roots: dict[str, Path], folder: Path, work: Path) -> dict[str, Path]:
    """The actor's synthesis models from its calibration captures (plain captures, stabilized
    with the actor), through the console: H's network calibrated through F, and the linear
    response fitted on the held expressions (no F): {name: model file}."""
    models = {"H_calibrated": folder / "H_calibrated.synthesis", "linear_response": folder / "linear_response.synthesis"}
    usdfacedyn("train-synthesis", *map(str, roots.values()), "-o", str(models["H_calibrated"]), "--calibrate", str(work / "H.synthesis"),
               "--quasistatic", str(work / f"{RECOMMENDED}.removal"), "--device", "cpu")
    usdfacedyn("train-synthesis", *map(str, roots.values()), "-o", str(models["linear_response"]), "--calibrate", str(work / "H.synthesis"),
               "--response", "linear")
    return models


def score(estimate, truth, fv) -> float:
    return round(residual_fraction(estimate, truth, truth, fv)["fraction"], 3)


def removal_case(actor_name: str, label: str, take: TestTake, models: dict, fv, bands: dict, chosen: str, response, session_choice: str) -> dict:
    truth = take.truth.offsets
    solved = take.stabilized.points
    result = {"case": "removal", "actor": actor_name, "test": label, "frames": len(truth),
              "dynamics_rms_mm": round(residual_fraction(truth, truth, truth, fv)["dynamics_rms_cm"] * 10, 3),
              "do_nothing": 1.0, "moving_average": score(dynamic_offsets(solved[:, fv], space="skull"), truth[:, fv], None)}
    for name, performance in take.removed.items():
        result[f"{name}_solved"] = score(performance.offsets, truth, fv)
        _, offsets = remove_dynamics(take.tracked_true_skull, take.truth.skull_translate, take.truth.skull_orient, take.truth.fps, models[name])
        result[f"{name}_true_skull_upper_bound"] = score(offsets, truth, fv)
    for name, model in bands.items():  # the family's F among them: its figure equals F_truth_acc_solved (the console's remove)
        result[f"{RECOMMENDED}_{name}_solved"] = score(remove_dynamics(solved, *take.stabilized.skull(), take.stabilized.fps, model)[1], truth, fv)
    if bands:
        result[f"{RECOMMENDED}_chosen_on_session_solved"] = result[f"{RECOMMENDED}_{chosen}_solved"]
    result["linear_response_solved"] = score(take.removed_by_response.offsets, truth, fv)
    _, offsets = remove_with_response(take.tracked_true_skull, take.truth.skull_translate, take.truth.skull_orient, take.truth.fps, response)
    result["linear_response_true_skull_upper_bound"] = score(offsets, truth, fv)
    result[f"{BLEND}_solved"] = score(take.removed_by_blend.offsets, truth, fv)
    chosen_key = {"linear_response": "linear_response_solved", "family": f"{RECOMMENDED}_solved", BLEND: f"{BLEND}_solved"}.get(
        session_choice, f"{RECOMMENDED}_{session_choice}_solved")
    result["removal_chosen_on_session_motion_left_solved"] = result[chosen_key]
    return result


def synthesis_case(actor_name: str, take: TestTake, h_model, response, fv) -> dict:
    truth = take.truth.offsets
    sim = take.truth
    _, upper = synthesize_dynamics(sim.quasistatic, sim.skull_translate, sim.skull_orient, sim.fps, h_model)
    # the response's expression term reads the quasistatic skin: from the true one, it cannot read back what removal left
    _, response_upper = synthesize_dynamics(sim.quasistatic, sim.skull_translate, sim.skull_orient, sim.fps, response)
    return {"case": "synthesis under new motion (CMU 131_03 hop)", "actor": actor_name, "frames": len(truth),
            "dynamics_rms_mm": round(residual_fraction(truth, truth, truth, fv)["dynamics_rms_cm"] * 10, 3),
            "no_dynamics": 1.0,
            "H_solved": score(take.synthesized["H"].offsets, truth, fv),
            "synthesized_rms_mm": round(residual_fraction(take.synthesized["H"].offsets, 0 * truth, truth, fv)["residual_rms_cm"] * 10, 3),
            "H_calibrated_solved": score(take.synthesized["H_calibrated"].offsets, truth, fv),
            "calibrated_rms_mm": round(residual_fraction(take.synthesized["H_calibrated"].offsets, 0 * truth, truth, fv)["residual_rms_cm"] * 10, 3),
            "linear_response_solved": score(take.synthesized["linear_response"].offsets, truth, fv),
            "linear_response_rms_mm": round(residual_fraction(take.synthesized["linear_response"].offsets, 0 * truth, truth, fv)["residual_rms_cm"] * 10, 3),
            "H_true_skull_true_quasistatic_upper_bound": score(upper, truth, fv),
            "linear_response_true_skull_true_quasistatic_upper_bound": score(response_upper, truth, fv)}


def retarget_case(source: tuple[str, TestTake], target: tuple[str, VolumetricParams, TestTake, dict], rig, models: Path, h_model, fv) -> dict:
    """A's capture retargeted onto B's quasistatic performance (the console's retarget, both
    methods), against B's tissue under A's true skull motion with B's own expression."""
    (a_name, a), (b_name, b_params, b, b_calibrated) = source, target
    y_b = rig.evaluate(b.truth.weights)
    truth_sim = volumetric.simulate(y_b, rig.topology.triangles(), a.truth.skull_translate, a.truth.skull_orient, a.truth.fps, b_params,
                                    rigid_weights=rig.rigid_weights, neutral=rig.neutral)
    truth = truth_sim.dynamics.astype(np.float32)
    folder = b.root.parent
    scores = {}
    methods = (("synthesis", ("--model", str(models / "H.synthesis"))), ("synthesis_calibrated", ("--model", str(b_calibrated["H_calibrated"]))),
               ("linear_response", ("--model", str(b_calibrated["linear_response"]))), ("delta_transfer", ("--method", "delta-transfer")))
    for method, flags in methods:
        layer = folder / f"retargeted.{method}.usdc"
        usdfacedyn("retarget", str(b.root), "--source", str(a.root), "-o", str(layer), *flags)
        scores[method] = score(read_layers_offsets(layer, b.root), truth, fv)
    quasistatic = (y_b + truth_sim.gravity_sag).astype(np.float32)
    _, upper = synthesize_dynamics(quasistatic, a.truth.skull_translate, a.truth.skull_orient, a.truth.fps, h_model)
    _, response_upper = synthesize_dynamics(quasistatic, a.truth.skull_translate, a.truth.skull_orient, a.truth.fps,
                                            load_model(b_calibrated["linear_response"]))
    return {"case": "retargeting A -> B (A: dialog under CMU 131_03 hop; B: its dialog under CMU 131_02 walk)", "source_actor": a_name,
            "target_actor": b_name, "frames": len(truth),
            "dynamics_rms_mm": round(residual_fraction(truth, truth, truth, fv)["dynamics_rms_cm"] * 10, 3),
            "no_dynamics": 1.0, "H_solved": scores["synthesis"], "delta_transfer_solved": scores["delta_transfer"],
            "ratio_to_delta_transfer": round(scores["synthesis"] / scores["delta_transfer"], 3),
            "H_calibrated_solved": scores["synthesis_calibrated"],
            "calibrated_ratio_to_delta_transfer": round(scores["synthesis_calibrated"] / scores["delta_transfer"], 3),
            "linear_response_solved": scores["linear_response"],
            "linear_response_ratio_to_delta_transfer": round(scores["linear_response"] / scores["delta_transfer"], 3),
            "delta_transfer_true_offsets_upper_bound": score(a.truth.offsets, truth, fv),
            "H_true_skull_true_quasistatic_upper_bound": score(upper, truth, fv),
            "linear_response_true_skull_true_quasistatic_upper_bound": score(response_upper, truth, fv)}


def read_layers_offsets(layer: Path, root: Path) -> np.ndarray:
    from facedyn.usd.take import read_layers

    return read_layers([layer, root]).offsets


def simulate_tests(rig, specs: dict[str, TakeSpec], params: VolumetricParams, jobs: int, actor_name: str, tag: dict, record: Recorder) -> dict:
    """{label: simulated take} of the specs; a take whose volumetric simulation diverges is
    reported (its cases are left out) instead of ending the run."""
    try:
        return dict(zip(specs, simulate_takes(rig, list(specs.values()), params, jobs=jobs)))
    except SimulationDiverged:
        pass  # one at a time, to learn which
    sims = {}
    for label, spec in specs.items():
        try:
            sims[label] = simulate_take(rig, spec, params)
        except SimulationDiverged as exc:
            record(dict(case="test take diverged", actor=actor_name, test=label, **tag, error=str(exc)))
    return sims


def run_actor(seed: int, k: int, held_out: bool, rig, work: Path, scratch: Path, models: dict, bands: dict, h_model, args,
              started: float, record: Recorder) -> tuple[str, VolumetricParams, dict, dict]:
    """One volumetric actor's calibration and test takes through the console, and its cases;
    (name, tissue, test takes, its synthesis models from the session). `bands`: candidate recommended F's by name
    ("family" and one per --soft-hz band), one chosen per actor on its calibration session."""
    fv = rig.face_vertices
    params = VolumetricParams.random(seed, substeps=2)  # one step per frame diverges on CMU hopping for some actors
    actor_name = f"volumetric_{seed}"
    tag = {"held_out": True} if held_out else {}
    record(dict(case="test actor", actor=actor_name, simulator="facedyn.sim.volumetric", **tag, soft_hz=round(params.soft_hz, 2),
                damping_ratio=round(params.damping_ratio, 3), thickness_cm=round(params.thickness_cm, 2), nonlinearity=round(params.nonlinearity, 2)))
    base = (6000 if held_out else 5000) + 10 * k
    specs = test_specs(args.seconds, base)
    calibration = calibration_specs(args.session_seconds, base, args.horizontal_platforms)
    t0 = time.perf_counter()
    sims = simulate_tests(rig, {**specs, **calibration}, params, args.jobs, actor_name, tag, record)
    simulated = time.perf_counter() - t0
    tests = scratch / actor_name  # test takes are never kept: a rerun simulates them afresh
    t0 = time.perf_counter()
    roots = {label: plain_capture(sims.pop(label), rig, tests / "calibration" / label, work / "actor.usda")[0]
             for label in calibration if label in sims}
    calibrated = session_models(roots, tests / "calibration", work)
    calibrating = time.perf_counter() - t0
    chosen, ratios = choose_removal(roots, calibration, band_paths(work, args), tests / "calibration") if bands else (None, {})
    if bands:
        record(dict(case="tissue band chosen on the calibration session", actor=actor_name, **tag, chosen=chosen, held_expression_spread_ratio=ratios))
    response = load_model(calibrated["linear_response"])
    session_choice, left = choose_on_session(roots, band_paths(work, args), calibrated["linear_response"], tests / "calibration")
    record(dict(case="removal chosen on the session's motion left", actor=actor_name, **tag, chosen=session_choice, session_motion_left=left))
    takes = {label: TestTake(sim, rig, tests / label, work / "actor.usda", work, calibrated["linear_response"]) for label, sim in sims.items()}
    for label in ("dialog_walk", "dialog_run", "platform_8hz"):
        if label in takes:
            record({**removal_case(actor_name, label, takes[label], models, fv, bands, chosen, response, session_choice), **tag})
    if "dialog_hop" in takes:
        for name, model in calibrated.items():
            takes["dialog_hop"].synthesized[name] = takes["dialog_hop"].synthesize(model, f"synthesized.{name}.usdc")
        record({**synthesis_case(actor_name, takes["dialog_hop"], h_model, response, fv), **tag})
    record(dict(case="test timing", actor=actor_name, **tag, simulate_seconds=round(simulated, 1), calibrate_seconds=round(calibrating, 1),
                total_seconds=round(time.perf_counter() - started, 1)))
    return actor_name, params, takes, calibrated


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--actors", type=int, default=2, choices=range(0, len(ACTOR_SEEDS) + 1),
                           help="volumetric actors of the seeds the training family was tuned against (0: only --held-out-actors)")
    arguments.add_argument("--held-out-actors", type=int, default=0, choices=range(0, len(HELD_OUT_SEEDS) + 1),
                           help="volumetric actors from seeds never used while tuning, reported with held_out: true (final figures only)")
    arguments.add_argument("--epochs", type=int, default=8, help="epochs of every F variant (equal budgets)")
    arguments.add_argument("--subsample", type=float, default=0.5, help="fraction of pairs per epoch, every F variant")
    arguments.add_argument("--h-epochs", type=int, default=20)
    arguments.add_argument("--seconds", type=float, default=1.5, help="length of each test take")
    arguments.add_argument("--session-seconds", type=float, default=SESSION_SECONDS, help="length of each calibration take (nine "
                           "held expressions: a 40 s session by default)")
    arguments.add_argument("--soft-hz-bands", type=lambda text: [b for b in text.split(",") if b], default=list(SOFT_HZ_BANDS),
                           help="comma-separated simulate --soft-hz bands: the recommended F trained once more per band, one of "
                           "them or the family's chosen per actor on its calibration session ('' for none)")
    arguments.add_argument("--horizontal-platforms", action="store_true", help="each actor's session shakes two platforms "
                           "horizontally instead (6 Hz -> 4 Hz side to side, 1 cm; 10 Hz -> 7 Hz fore and aft, 0.4 cm)")
    arguments.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    arguments.add_argument("--work", type=Path, help="keep the corpus, actor and models in this folder and reuse them when there "
                           "(a rerun tests again without training; default: a temporary folder)")
    args = arguments.parse_args()
    if not DATA.is_dir():
        raise SystemExit(f"{DATA}: the shared data (Live Link speech, CMU mocap) is needed")
    from facedyn.usd.blendshape_rig import write_blendshape_rig

    rig = default_face()
    fv = rig.face_vertices
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="facedyn-cross-sim-") as scratch, Recorder("bench_cross_sim", args) as record:
        work = args.work or Path(scratch)
        work.mkdir(parents=True, exist_ok=True)
        if (work / "H.synthesis").is_file():
            seconds = "reused from an earlier run in --work"
        else:
            seconds = train(work, write_blendshape_rig(rig, work / "rig.usda"), args)
        band_seconds = train_bands(work, work / "rig.usda", args)
        corpus = json.loads((work / "corpus" / "corpus.json").read_text())
        trained = [t for t in corpus["takes"] if t["name"] not in TEST_SPEECH_TAKES.split(",")]
        record(dict(case="training", simulator="facedyn.sim.tissue, random TissueParams per take", rig=rig.name,
                    takes=len(trained), frames=int(sum(t.get("frames", 0) for t in trained)), f_epochs=args.epochs, f_subsample=args.subsample,
                    h_epochs=args.h_epochs, seconds=seconds, soft_hz_bands=args.soft_hz_bands, band_seconds=band_seconds or "reused", budget="every F variant: the same epochs and subsample fraction; the paper's F without the talking takes",
                    session="two platforms shaken horizontally (--horizontal-platforms)" if args.horizontal_platforms else "five vertical platforms"))
        models = {name: load_model(work / f"{name}.removal") for name in F_VARIANTS}
        h_model = load_model(work / "H.synthesis")
        bands = {name: load_model(path) for name, path in band_paths(work, args).items()} if args.soft_hz_bands else {}
        groups = [(False, ACTOR_SEEDS[: args.actors]), (True, HELD_OUT_SEEDS[: args.held_out_actors])]
        for held_out, seeds in groups:
            actors = [run_actor(seed, k, held_out, rig, work, Path(scratch), models, bands, h_model, args, started, record) for k, seed in enumerate(seeds)]
            for (a_name, _, a_takes, _), (b_name, b_params, b_takes, b_calibrated) in zip(actors[:-1], actors[1:]):
                if "dialog_hop" not in a_takes or "dialog_walk" not in b_takes:
                    continue  # reported as diverged above
                try:
                    case = retarget_case((a_name, a_takes["dialog_hop"]), (b_name, b_params, b_takes["dialog_walk"], b_calibrated), rig, work, h_model, fv)
                except SimulationDiverged as exc:
                    case = {"case": "retargeting truth diverged", "source_actor": a_name, "target_actor": b_name, "error": str(exc)}
                record({**case, **({"held_out": True} if held_out else {})})


if __name__ == "__main__":
    main()
