"""How far an actor's linear response can reach on the test set's run, fitted on the truth itself.

Synthesis (a quasistatic take under a new skull) and retargeting read the actor's linear
response (facedyn.dynamics.response), fitted on its calibration session. On the validation
actors it leaves 40-51 % of the moving dynamics of the transfer take (the walking dialog under
the run; issue 37's target: 30 %). This measures whether a better fit of the same model could
do better, on the actor's own MuJoCo tissue (benchmarks/README-testset.md), with the true
skull, each case fitted as calibrate fits it (`fit_linear_response`):

- ``session captures``: on the session's true captured skin (no tracker noise), the ridge the
  session chooses;
- ``session truth``: on the session's true dynamics (no expression, no noise), the ridge the
  session chooses: the best a truth-free fit on this session could hope for (an upper bound);
- ``half-size run truth``: on the true dynamics of the test's run simulated again with its
  skull motion halved about its steady path (testset.takes.scaled_about_steady_path): the same
  motion at about the session's amplitude; ``session and half-size run truth``: both;
- ``full-size run truth, in sample``: on the run's own true dynamics: what the model's form
  holds of that run at all.

The lone runs take the session truth's ridge (one take has no other to choose by). Each is
scored on the run at full size (CMU 131_02 at 1.6x, the test's dialog) as `synthesize` answers
it from the run's true quasistatic skin and true skull (facedyn.dynamics.synthesis): the
fraction of the true dynamics' moving part (each side less its mean over the take: the static
share set apart, testset.score.moving_left) left on the face vertices.
If the run's own truth, fitted in sample, leaves more than the target, no fit of a linear
response reaches it there: the tissue answers the run's larger motion nonlinearly.

    python benchmarks/testset_ceiling.py ACTOR_FOLDER [--session FOLDER] [--out benchmarks/results/testset_ceiling.json]

ACTOR_FOLDER: a validation actor from testset_generate.py (its rig and takes); --session: the
folder holding its session takes' truth if not the same (an actor whose 70-take session was
generated apart). Validation actors only: a test actor's tissue is not to be probed.
"""
from __future__ import annotations

import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from harness import Recorder, parser
from testset.actors import ACTORS, FPS, SUBSTEPS, test_takes
from testset.generate import actor_rig, simulate_take
from testset.score import load_truth, moving_left
from testset.tissue import MujocoTissue, TissueParams

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.response import fit_linear_response, response_template
from facedyn.dynamics.synthesis import synthesize_dynamics
from facedyn.dynamics.training_sequence import TrainingSequence
from facedyn.processors.calibrate import F_SAMPLES

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
HALF = 0.5


def session_truths(folder: Path) -> list[tuple[str, dict]]:
    takes = sorted(path.parent.name for path in (folder / "takes").glob("session_*/truth.npz"))
    if not takes:
        raise SystemExit(f"{folder}: no session takes (takes/session_*/truth.npz); generate them with testset_generate.py --takes session")
    return [(take, load_truth(folder, take)) for take in takes]


def as_take(name: str, truth: dict, points: np.ndarray) -> TrainingSequence:
    """A take of skull-space points under the truth's skull."""
    return TrainingSequence(name, points, float(truth["fps"]), truth["skull_translate"], truth["skull_orient"], "skull")


def synthesized(model, truth: dict) -> np.ndarray:
    """(F, N, 3) what `synthesize` makes of a take's true quasistatic skin under its true skull."""
    _, offsets = synthesize_dynamics(truth["quasistatic"], truth["skull_translate"], truth["skull_orient"], float(truth["fps"]), model,
                                     "numpy")
    return offsets


def actor_name(folder: Path) -> str:
    spec = folder / "actor.json"
    if not spec.is_file():
        raise SystemExit(f"{folder}: no actor.json (an actor folder from testset_generate.py)")
    name = json.loads(spec.read_text())["actor"]["name"]
    if name not in ACTORS or ACTORS[name].split != "validation":
        raise SystemExit(f"{folder}: {name!r} is not a validation actor (testset.actors); a test actor's tissue is not probed")
    return name


def validation_actor(doc: str):
    """(arguments, actor name, its spec, its rig, its face with F's samples) of a benchmark run on
    one validation actor's folder, with --session for its session takes if they lie apart."""
    arguments = parser(doc)
    arguments.add_argument("actor", type=Path, help="a validation actor's folder (testset_generate.py)")
    arguments.add_argument("--session", type=Path, help="the folder with its session takes, if not the actor's")
    args = arguments.parse_args()
    name = actor_name(args.actor)
    spec = ACTORS[name]
    rig = actor_rig(spec, DATA)
    face = FaceSetup.build(rig.topology, rig.neutral, rigid_weights=rig.rigid_weights, face_vertices=rig.face_vertices,
                           sample_count=F_SAMPLES)
    return args, name, spec, rig, face


def main() -> None:
    args, name, spec, rig, face = validation_actor(__doc__)
    template = response_template(face, FPS)
    session = session_truths(args.session or args.actor)
    neutral = np.asarray(rig.neutral, np.float64)

    started = time.perf_counter()
    tissue = MujocoTissue(rig.neutral, rig.topology.triangles(), rig.face_vertices, TissueParams.random(spec.tissue_seed),
                          1.0 / (FPS * SUBSTEPS[spec.face]))
    _, run, _ = test_takes(spec.take_seed)
    runs = {scale: simulate_take(rig, tissue, replace(run, motion_scale=scale), DATA) for scale in (HALF, 1.0)}
    simulated = time.perf_counter() - started
    scored = runs[1.0]
    dynamics = np.asarray(scored["dynamics"], np.float64)[:, scored["face_vertices"]]

    def on_truth(label: str, truth: dict) -> TrainingSequence:
        return as_take(label, truth, neutral + truth["dynamics"])

    session_truth = [on_truth(take, truth) for take, truth in session]
    half = on_truth("run_half", runs[HALF])
    cases = [("session captures", [as_take(take, truth, truth["captured"]) for take, truth in session], True),
             ("session truth", session_truth, True),
             ("half-size run truth", [half], False),
             ("session and half-size run truth", session_truth + [half], True),
             ("full-size run truth, in sample", [on_truth("run", scored)], False)]
    session_ridge = None
    with Recorder("testset_ceiling", args) as emit:
        for label, takes, chooses in cases:
            began = time.perf_counter()
            model = fit_linear_response(template, takes, ridge=None if chooses else session_ridge)
            record = model.info["calibration"]
            if label == "session truth":
                session_ridge = record["ridge"]
            emit({"case": f"{name}: fitted on {label}", "actor": name, "fitted_on": label, "takes": len(takes),
                  "ridge": record["ridge"], "hardening": round(record["hardening"], 3),
                  "run_moving_left": round(moving_left(synthesized(model, scored), scored), 4),
                  "run_moving_rms_mm": round(float(np.sqrt(((dynamics - dynamics.mean(0)) ** 2).sum(-1).mean()) * 10), 3),
                  "fit_seconds": round(time.perf_counter() - began, 1), "simulation_seconds": round(simulated, 1),
                  "obtained": {"skull": "true", "rest": "given (the actor's rig)",
                               "scored": "synthesize of the run's true quasistatic skin under its true skull (CMU 131_02 at "
                                         "1.6x, the test's dialog, full size), face vertices, moving part (static share set apart)",
                               "test data": "MuJoCo flex tissue over the actor's own bone (benchmarks/testset), true dynamics",
                               "split": "validation actor", "model": "facedyn.dynamics.response.fit_linear_response"}})


if __name__ == "__main__":
    main()
