"""What spreading offsets from the samples to the mesh loses, with the bi-Laplacian and with the actor's learned spread.

Every model predicts offsets at F's skin samples (344 on the built-in face) and spreads them
to every vertex (facedyn.dynamics.propagate, the smoothest field through them); calibrate
adds the actor's spread learned on its session (facedyn.dynamics.spread). This takes each
validation actor's *true* dynamics on its test takes, keeps them at the samples only and
spreads them back, so what is lost is the spread's alone (a perfect model at the samples
would lose as much):

- ``bi-Laplacian``, at the model's samples and at twice and four times as many;
- ``learned spread``: the bi-Laplacian plus the spread fitted as calibrate fits it, on the
  actor's stabilized session (solved skull, tracker noise, no truth).

Figures: the fraction of the true dynamics' moving part left on the face vertices
(testset.score.moving_left), per test take.

    python benchmarks/testset_spread.py --actor ACTOR_FOLDER SESSION_WORK FAMILY_MODEL [--actor ...] [--out FILE]

SESSION_WORK: the folder of the actor's stabilized session takes (session_*/take.usda, as
calibrate reads them); FAMILY_MODEL: the family F calibrate trained for it (its samples).
Validation actors only (README-testset.md).
"""
from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from harness import Recorder, parser
from testset.score import load_truth, moving_left
from testset_ceiling import actor_name

from facedyn.dynamics.face import FaceSetup
from facedyn.dynamics.modelfile import load_model
from facedyn.dynamics.propagate import build_propagator
from facedyn.dynamics.response import SETTLE_S
from facedyn.dynamics.spread import fit_spread
from facedyn.dynamics.training_sequence import TrainingSequence
from facedyn.performance import QUASISTATIC
from facedyn.processors.training_inputs import take_name
from facedyn.usd.take import read_take_below

TAKES = ("dialog_walk", "dialog_run", "platform_8hz")
DENSER = (2, 4)  # bi-Laplacian at this many times the model's samples


def spread_back(truth: dict, samples: np.ndarray, propagator) -> np.ndarray:
    """(F, N, 3) the true dynamics kept at the samples and spread to every vertex."""
    dynamics = np.asarray(truth["dynamics"], np.float32)
    return propagator.apply(dynamics[:, samples]).astype(np.float64)


def main() -> None:
    arguments = parser(__doc__)
    arguments.add_argument("--actor", nargs=3, action="append", required=True, type=Path, metavar=("ACTOR", "SESSION_WORK", "FAMILY"),
                           help="a validation actor's folder, its stabilized session's folder and its family F")
    args = arguments.parse_args()
    with Recorder("testset_spread", args) as emit:
        for folder, work, family in args.actor:
            name = actor_name(folder)
            model = load_model(family)
            truths = {take: load_truth(folder, take) for take in TAKES}
            obtained = {"skull": "none (the true dynamics, kept at the samples)", "rest": "given (the actor's rig)",
                        "scored": "each test take's moving part (static share set apart), face vertices",
                        "test data": "MuJoCo flex tissue over the actor's own bone (benchmarks/testset), true dynamics",
                        "split": "validation actor"}

            def record(label: str, samples: np.ndarray, propagator, **extra) -> None:
                emit({"case": f"{name}: {label}", "actor": name, "spread": label, "samples": int(len(samples)),
                      **{take: round(moving_left(spread_back(truth, samples, propagator), truth), 4) for take, truth in truths.items()},
                      **extra, "obtained": obtained})

            plain = model.propagator()
            record("bi-Laplacian", model.face.samples, plain)
            for factor in DENSER:
                face = FaceSetup.build(model.face.topology, model.face.rest_points, rigid_vertices=model.face.rigid_vertices,
                                       face_vertices=truths[TAKES[0]]["face_vertices"], sample_count=factor * len(model.face.samples))
                record(f"bi-Laplacian, {factor}x the samples", face.samples,
                       build_propagator(face.rest_points, face.topology.triangles(), face.samples, face.rigid_vertices))
            began = time.perf_counter()
            roots = sorted(Path(work).glob("session_*/take.usda"))
            takes = [TrainingSequence.from_performance(read_take_below(root, QUASISTATIC)[0], take_name(root)) for root in roots]
            spread, fitted = fit_spread(takes, plain, int(round(SETTLE_S * model.fps)))
            record("learned spread (calibrate's, on the stabilized session)", model.face.samples, replace(plain, spread=spread),
                   session_takes=len(takes), fit_seconds=round(time.perf_counter() - began, 1), **fitted)


if __name__ == "__main__":
    main()
